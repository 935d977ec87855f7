"""certificate.html and certificate.pdf: written beside the JSON for a simulated run, the
PDF's text and attachment read back with poppler (pdftotext, pdfdetach)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from hil.characterise.processes import run_command
from hil.gum import rounded_pair
from hil.profile import builtin_profile_path
from hil.report.plots import PLOTTERS
from tests.report.runs import Run, calibrate

POPPLER = shutil.which("pdftotext") is not None and shutil.which("pdfdetach") is not None
needs_poppler = pytest.mark.skipif(
    not POPPLER, reason="poppler-utils (pdftotext, pdfdetach) not installed: "
                        "apt-get install -y poppler-utils")


def pdf_pages(path: Path) -> list[str]:
    text = subprocess.run(["pdftotext", "-layout", str(path), "-"], capture_output=True,
                          text=True, check=True).stdout
    return [page for page in text.split("\f") if page.strip()]


def flat(text: str) -> str:
    return " ".join(text.split())


def certificate(run: Run) -> dict:  # type: ignore[type-arg]
    return json.loads((run.unit_dir / "certificate.json").read_text(encoding="utf-8"))


def plotted(cert: dict) -> set[str]:  # type: ignore[type-arg]
    return {name for name, p in cert["method"]["protocols"].items()
            if p["outcome"] != "SKIPPED" and name in PLOTTERS}


def test_html_is_self_contained_with_a_plot_per_protocol(elevation_run: Run) -> None:
    cert = certificate(elevation_run)
    html = (elevation_run.unit_dir / "certificate.html").read_text(encoding="utf-8")
    assert cert["certificate_id"] in html
    assert not re.search(r'(src|href)="(?!data:)', html), "an external reference"
    captions = set(re.findall(r"<figcaption>(\w+) \(", html))
    assert captions == plotted(cert) == {"current_loop", "gravity_cable", "inertia_friction",
                                         "stribeck", "cogging", "torque_constant",
                                         "velocity_loop_frf", "velocity_step", "tracking",
                                         "standstill", "cogging_compensation"}
    assert html.count('src="data:image/png;base64,') == len(captions)
    for r in cert["results"]:
        value, expanded = rounded_pair(r["value"], r["expanded_uncertainty"])
        assert f"<td class=n>{value}</td><td class=n>{expanded}</td>" in html, r["parameter"]


@needs_poppler
def test_pdf_pages_carry_id_and_page_x_of_y(elevation_run: Run) -> None:
    cert = certificate(elevation_run)
    pages = pdf_pages(elevation_run.unit_dir / "certificate.pdf")
    assert len(pages) >= 2
    for number, page in enumerate(pages, start=1):
        assert cert["certificate_id"] in page
        assert f"page {number} of {len(pages)}" in page


@needs_poppler
def test_pdf_results_are_gum_rounded_with_the_conformity_statement(elevation_run: Run) -> None:
    cert = certificate(elevation_run)
    text = "\n".join(pdf_pages(elevation_run.unit_dir / "certificate.pdf"))
    lines = [line.split() for line in text.splitlines()]
    for r in cert["results"]:
        value, expanded = rounded_pair(r["value"], r["expanded_uncertainty"])
        row = [r["parameter"], value, expanded, f"{r['coverage_factor']:.2f}"]
        # the code name follows the result's title in its row
        assert any(tokens[i:i + 4] == row for tokens in lines for i in range(len(tokens))), row
    assert flat(cert["conformity"]) in flat(text)
    assert flat(cert["decision_rule"]) in flat(text)
    for name in plotted(cert):
        assert f"{name} ({cert['method']['protocols'][name]['outcome']})" in text


@needs_poppler
def test_every_document_tells_how_often_a_result_s_u_held_the_truth(elevation_run: Run) -> None:
    """The map's out-of-sample check under each budget, in the HTML and the PDF as in the
    TXT (the HTML and PDF left it out)."""
    cert = certificate(elevation_run)
    validated = [r for r in cert["results"] if r.get("validation")]
    assert validated
    html = (elevation_run.unit_dir / "certificate.html").read_text(encoding="utf-8")
    pdf = flat("\n".join(pdf_pages(elevation_run.unit_dir / "certificate.pdf")))
    for r in validated:
        check = r["validation"]
        sentence = (f"validated: ±U held the truth for {100 * check['coverage']:.0f} % of "
                    f"{check['units']} simulated units")
        assert sentence in html, r["parameter"]
        assert flat(sentence) in pdf, r["parameter"]
    assert html.count("validated: ±U held the truth") == len(validated)


@needs_poppler
def test_the_json_attached_to_the_pdf_is_the_certificate(elevation_run: Run,
                                                         tmp_path: Path) -> None:
    subprocess.run(["pdfdetach", "-saveall", "-o", str(tmp_path),
                    str(elevation_run.unit_dir / "certificate.pdf")], check=True)
    attached = (tmp_path / "certificate.json").read_bytes()
    assert attached == (elevation_run.unit_dir / "certificate.json").read_bytes()


@needs_poppler
def test_a_failed_run_says_fail_on_every_page(failed_run: Run) -> None:
    cert = certificate(failed_run)
    assert cert["outcome"] == "FAIL"
    pages = pdf_pages(failed_run.unit_dir / "certificate.pdf")
    first = pages[0].splitlines()
    banner = next(line for line in first if "FAIL" in line or "PASS" in line)
    assert "FAIL" in banner
    assert "PASS" not in banner
    assert "does NOT conform" in pages[0]
    for page in pages:
        footer = next(line for line in reversed(page.splitlines()) if line.strip())
        assert "FAIL" in footer
        assert "PASS" not in footer
    html = (failed_run.unit_dir / "certificate.html").read_text(encoding="utf-8")
    assert f"{cert['certificate_id']} (FAIL)</title>" in html


def test_the_console_shows_progress_and_a_banner(elevation_run: Run) -> None:
    from hil.report.console import block_letters

    out = elevation_run.stdout
    cert = certificate(elevation_run)
    ran = [n for n, p in cert["method"]["protocols"].items() if p["outcome"] != "SKIPPED"]
    for number, name in enumerate(ran, start=1):
        assert f"▶ protocol {number} of {len(ran)}: {name} (" in out
    for row in block_letters("PASS"):
        assert row in out
    for r in cert["results"]:
        value, expanded = rounded_pair(r["value"], r["expanded_uncertainty"])
        assert f"{value} ± {expanded}" in out
    assert re.search(r"^\d+ passed, \d+ skipped in ", out, re.MULTILINE), "pytest's summary"


def test_the_failed_console_banner_says_fail(failed_run: Run) -> None:
    from hil.report.console import block_letters

    for row in block_letters("FAIL"):
        assert row in failed_run.stdout
    assert "unit RPT-FAIL: FAIL" in failed_run.stdout


def _copy(run: Run, tmp_path: Path) -> Path:
    unit_dir = tmp_path / run.unit_dir.name
    shutil.copytree(run.unit_dir, unit_dir)
    for name in ("certificate.html", "certificate.pdf"):
        (unit_dir / name).unlink()
    return unit_dir


def _write_documents(unit_dir: Path, *, block_typst: bool) -> str:
    code = ("import sys\n" + ("sys.modules['typst'] = None\n" if block_typst else "")
            + "from pathlib import Path\nfrom hil.report.documents import write_documents\n"
            "print(write_documents(Path(sys.argv[1])))\n")
    done = subprocess.run([sys.executable, "-c", code, str(unit_dir / "certificate.json")],
                          capture_output=True, text=True, timeout=300, check=True)
    return done.stdout


def test_without_typst_the_json_stands_and_the_failure_is_named(failed_run: Run,
                                                               tmp_path: Path) -> None:
    unit_dir = _copy(failed_run, tmp_path)
    record = (unit_dir / "certificate.json").read_bytes()
    said = _write_documents(unit_dir, block_typst=True)
    assert "certificate.pdf not written: the typst package is not installed" in said
    assert not (unit_dir / "certificate.pdf").exists()
    assert (unit_dir / "certificate.html").exists()
    assert (unit_dir / "certificate.json").read_bytes() == record


def test_a_bad_recording_costs_its_plot_not_the_documents(failed_run: Run,
                                                          tmp_path: Path) -> None:
    unit_dir = _copy(failed_run, tmp_path)
    (sine,) = unit_dir.glob("recordings/inertia_friction__sine_2hz_1rad_s.csv.gz")
    sine.write_bytes(sine.read_bytes()[:200])
    said = _write_documents(unit_dir, block_typst=False)
    assert "plot of inertia_friction not drawn" in said
    assert (unit_dir / "certificate.pdf").exists()
    assert (unit_dir / "certificate.html").exists()


def test_the_resonance_run_carries_its_bode_plot(tmp_path: Path) -> None:
    run = calibrate(tmp_path, "RPT-AZ", "--profile", "demo_gimbal_azimuth", "--", "-k",
                    "resonance")
    assert run.returncode in (0, 1), run.stdout
    html = (run.unit_dir / "certificate.html").read_text(encoding="utf-8")
    assert re.findall(r"<figcaption>(\w+) \(", html) == ["resonance"]
    assert (run.unit_dir / "certificate.pdf").stat().st_size > 0


@needs_poppler
def test_an_unfinished_run_says_not_completed(tmp_path: Path) -> None:
    """A command beyond the unit's velocity limit is refused before motion: no result."""
    text = builtin_profile_path().read_text(encoding="utf-8")
    profile = tmp_path / "unit.toml"
    profile.write_text(text.replace("velocity_rad_s = 3.0", "velocity_rad_s = 0.8"),
                       encoding="utf-8")
    run = calibrate(tmp_path, "RPT-ERR", "--profile", str(profile), "--", "-k",
                    "inertia_friction")
    assert run.returncode != 0
    assert certificate(run)["outcome"] == "ERROR"
    pages = pdf_pages(run.unit_dir / "certificate.pdf")
    assert "NOT COMPLETED" in pages[0]
    assert "No results" in pages[0]
    for page in pages:
        footer = next(line for line in reversed(page.splitlines()) if line.strip())
        assert "NOT COMPLETED" in footer
    html = (run.unit_dir / "certificate.html").read_text(encoding="utf-8")
    assert "(NOT COMPLETED)</title>" in html
    assert "NOT COMPLETED" in run.stdout


def test_render_rewrites_the_documents_of_a_written_certificate(failed_run: Run,
                                                               tmp_path: Path) -> None:
    unit_dir = _copy(failed_run, tmp_path)
    done = run_command(["render", str(unit_dir)], timeout_s=300)
    assert done.returncode == 0, done.stderr
    assert (unit_dir / "certificate.pdf").exists()
    assert (unit_dir / "certificate.html").exists()
    not_one = tmp_path / "notes.json"
    not_one.write_text('{"schema": "something/else"}', encoding="utf-8")
    done = run_command(["render", str(not_one)], timeout_s=60)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"gimbal-hil: error: {not_one}: not a gimbal-hil certificate (schema 'something/else')"]
