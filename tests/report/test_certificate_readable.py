"""The certificate a customer reads without a glossary (issue 24): every result titled and
described with its code name beside it, the laboratory's fields from the station file,
"not authorised" when no one authorised it, no Python literals, no paths of the machine
that ran it, no unlabelled lines, no trailing decimal points, one-sided limits, skipped
protocols once with their reason, no table split to a page of its own, legends off the data."""

from __future__ import annotations

import copy
import importlib
import json
import pkgutil
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import pytest

from hil.certificate.render import render_text
from hil.config import builtin_fixture, read_toml
from hil.drives.station import load_station_identity
from hil.errors import ProfileError
from hil.report.data import from_certificate
from hil.report.figures import styled
from hil.report.plots import protocol_figure
from hil.report.view import certificate_view
from tests.helpers import subset_profile
from tests.report.runs import Run, calibrate

POPPLER = shutil.which("pdftotext") is not None
needs_poppler = pytest.mark.skipif(not POPPLER, reason="poppler-utils (pdftotext) not installed")
# the protocols whose plots this suite's identification half draws (plots_motion/frequency)
IDENTIFICATION_PLOTS = ("current_loop", "gravity_cable", "inertia_friction", "cogging",
                        "stribeck", "torque_constant")
TRAILING_POINT = re.compile(r"\d\.(?=\s|$|\)|,)", re.MULTILINE)  # "18." but not "7.8" or "3.1 s"
ABSOLUTE_PATH = re.compile(r"(?<![\w.])/(?:tmp|work|home|root|usr|var|opt|Users)/")
LITERALS = re.compile(r"\b(True|False|None)\b")


def certificate(run: Run) -> dict[str, Any]:
    return dict(json.loads((run.unit_dir / "certificate.json").read_text(encoding="utf-8")))


class _Text(HTMLParser):
    """The text a browser shows (no tags, no attributes: the plots' base64 stays out)."""

    def __init__(self) -> None:
        super().__init__()
        self.parts: list[str] = []

    def handle_data(self, data: str) -> None:
        self.parts.append(data)


def html_text(run: Run) -> str:
    parser = _Text()
    parser.feed((run.unit_dir / "certificate.html").read_text(encoding="utf-8"))
    return "\n".join(parser.parts)


def txt(run: Run) -> str:
    return (run.unit_dir / "certificate.txt").read_text(encoding="utf-8")


def pdf_pages(path: Path) -> list[str]:
    text = subprocess.run(["pdftotext", "-layout", str(path), "-"], capture_output=True,
                          text=True, check=True).stdout
    return [page for page in text.split("\f") if page.strip()]


# -- 1. titles and descriptions -------------------------------------------------------------

def protocol_modules() -> list[Any]:
    suite = importlib.import_module("gimbal_hil_protocols")  # the installed protocols/
    return [importlib.import_module(f"gimbal_hil_protocols.{m.name}")
            for m in pkgutil.iter_modules(suite.__path__) if m.name.startswith("test_")]


def test_every_declared_measurement_has_a_title_and_a_description() -> None:
    declared: set[str] = set()
    for module in protocol_modules():
        found = module.DECLARED
        assert set(found) == set(module.MEASUREMENTS), module.__name__
        for name, d in found.items():
            assert d.name == name
            assert d.title.strip(), name
            assert d.title != name, name
            assert d.description.strip(), name
            assert "\n" not in d.description, f"{name}: one line"
        declared |= set(found)
    assert len(declared) >= 39
    for profile in ("demo_gimbal_elevation.toml", "demo_gimbal_azimuth.toml"):
        document, _ = read_toml(builtin_fixture(profile))
        assert set(document["measurements"]) <= declared, profile


def test_the_certificate_shows_titles_beside_code_names(elevation_run: Run) -> None:
    cert = certificate(elevation_run)
    inertia = next(r for r in cert["results"] if r["parameter"] == "inertia_kg_m2")
    assert inertia["title"] == "Moment of inertia"
    assert "sinusoidal-velocity" in inertia["description"]
    text = txt(elevation_run)
    row = next(line for line in text.splitlines() if line.startswith("Moment of inertia"))
    assert row.rstrip().endswith("inertia_kg_m2")
    assert inertia["description"] in text
    html = (elevation_run.unit_dir / "certificate.html").read_text(encoding="utf-8")
    assert 'Moment of inertia<span class="code">inertia_kg_m2</span>' in html
    assert inertia["description"] in html


@needs_poppler
def test_the_pdf_shows_titles_and_descriptions(elevation_run: Run) -> None:
    cert = certificate(elevation_run)
    flat = " ".join("\n".join(pdf_pages(elevation_run.unit_dir / "certificate.pdf")).split())
    for r in cert["results"]:
        assert f"{r['title']} {r['parameter']}" in flat, r["parameter"]
        assert " ".join(r["description"].split()) in flat, r["parameter"]


def test_an_old_certificate_without_titles_reads_with_its_code_names(elevation_run: Run
                                                                     ) -> None:
    old = copy.deepcopy(certificate(elevation_run))
    for r in old["results"]:
        for key in ("title", "description", "non_negative"):
            r.pop(key)
    for key in ("laboratory", "customer", "authorised_by", "environment"):
        old.pop(key)
    old["method"]["profile"] = "/home/line/profiles/demo_gimbal_elevation.toml"
    view = certificate_view(old)
    assert view["results"][0]["title"] == old["results"][0]["parameter"]
    text = render_text(old)
    assert "demo_gimbal_elevation.toml (SHA-256" in text
    assert "/home/line" not in text
    assert "not authorised" in text


# -- 2. the laboratory's fields from the station file ---------------------------------------

STATION = """[station]
id = "EOL-3"
laboratory = "Acme Gimbals, calibration laboratory"
laboratory_address = "7 Test Lane, 4000 Basel"
customer = "Orbital Optics AG"
authorised_by = "R. Keller, quality manager"
temperature_c = 22.5
humidity_pct = 41
conditions = "air-conditioned, 23 ± 2 °C"
"""


def test_the_station_file_declares_laboratory_customer_authoriser_and_conditions(
        tmp_path: Path) -> None:
    path = tmp_path / "bench.toml"
    path.write_text(STATION, encoding="utf-8")
    identity = load_station_identity(path)
    assert identity.laboratory == "Acme Gimbals, calibration laboratory"
    assert identity.laboratory_address == "7 Test Lane, 4000 Basel"
    assert identity.customer == "Orbital Optics AG"
    assert identity.authorised_by == "R. Keller, quality manager"
    assert (identity.temperature_c, identity.humidity_pct) == (22.5, 41.0)
    path.write_text(STATION.replace("laboratory =", "laboratry ="), encoding="utf-8")
    with pytest.raises(ProfileError, match=r"bench.toml.*\[station\] has an unknown setting "
                                           r"'laboratry' \(did you mean 'laboratory'\?\)"):
        load_station_identity(path)
    path.write_text(STATION.replace("humidity_pct = 41", "humidity_pct = 140"), encoding="utf-8")
    with pytest.raises(ProfileError, match=r"\[station\] 'humidity_pct'"):
        load_station_identity(path)


@pytest.fixture(scope="module")
def station_run(tmp_path_factory: pytest.TempPathFactory) -> Run:
    out = tmp_path_factory.mktemp("station")
    (out / "bench.toml").write_text(STATION, encoding="utf-8")
    run = calibrate(out, "RPT-LAB", "--station", str(out / "bench.toml"), "--operator", "mia",
                    "--profile", str(subset_profile(out / "profiles", "current_loop")),
                    "--", "--store", "off")
    assert run.returncode == 0, run.stdout
    return run


def test_the_certificate_carries_the_station_files_fields(station_run: Run) -> None:
    cert = certificate(station_run)
    assert cert["laboratory"] == {"name": "Acme Gimbals, calibration laboratory",
                                  "address": "7 Test Lane, 4000 Basel"}
    assert cert["customer"] == "Orbital Optics AG"
    assert cert["authorised_by"] == "R. Keller, quality manager"
    assert cert["environment"] == {"temperature_c": 22.5, "humidity_pct": 41.0,
                                   "note": "air-conditioned, 23 ± 2 °C"}
    for text in (txt(station_run), html_text(station_run)):
        assert "Acme Gimbals, calibration laboratory, 7 Test Lane, 4000 Basel" in text
        assert "Orbital Optics AG" in text
        assert "R. Keller, quality manager" in text
        assert "temperature 22.5 °C, relative humidity 41 %" in text
        assert "station EOL-3, operator mia" in text
        assert "not authorised" not in text.lower()


@needs_poppler
def test_without_an_authoriser_every_page_says_not_authorised(elevation_run: Run) -> None:
    assert certificate(elevation_run)["authorised_by"] is None
    assert "OUTCOME: PASS (not authorised)" in txt(elevation_run)
    assert "NOT AUTHORISED" in html_text(elevation_run)
    pages = pdf_pages(elevation_run.unit_dir / "certificate.pdf")
    assert "NOT AUTHORISED" in pages[0]
    for page in pages:
        header = next(line for line in page.splitlines() if line.strip())
        assert "not authorised" in header


# -- 3. what a customer finds odd -----------------------------------------------------------

def test_no_python_literals_machine_paths_or_trailing_points(elevation_run: Run) -> None:
    for name, text in (("txt", txt(elevation_run)), ("html", html_text(elevation_run))):
        assert not LITERALS.search(text), (name, LITERALS.search(text))
        assert not ABSOLUTE_PATH.search(text), (name, ABSOLUTE_PATH.search(text))
        assert str(elevation_run.unit_dir) not in text, name
        found = TRAILING_POINT.search(text)
        assert found is None, (name, text[max(found.start() - 60, 0):found.end() + 20])
        assert "simulated: yes" in text, name
        assert "demo_gimbal_elevation.toml (SHA-256 " in text, name
    # the record too: the files it names (the compensation table, the passes analysed)
    # are named within the unit's folder, not where the folder lay on this machine
    record = (elevation_run.unit_dir / "certificate.json").read_text(encoding="utf-8")
    assert str(elevation_run.unit_dir.parent) not in record
    assert not re.search(r'": "/', record), re.search(r'.{60}": "/.{60}', record)
    accreditation = next(line for line in txt(elevation_run).splitlines()
                         if "none claimed" in line)
    assert accreditation.startswith("Accreditation")
    assert "/" not in certificate(elevation_run)["method"]["profile"]


def test_two_digit_uncertainties_have_no_trailing_point(elevation_run: Run) -> None:
    from hil.gum import significant  # new with this test

    cert = copy.deepcopy(certificate(elevation_run))
    r = next(r for r in cert["results"] if r["parameter"] == "tracking_peak_error_urad")
    r["standard_uncertainty"], r["expanded_uncertainty"] = 18.0, 36.0
    r["budget"][0]["standard_uncertainty"] = r["budget"][0]["contribution"] = 17.0
    text = render_text(cert)
    assert "u = 18 µrad" in text
    assert "u(x) = 17 " in text
    assert not TRAILING_POINT.search(text)
    budget = next(b for b in certificate_view(cert)["budgets"]
                  if b["parameter"] == "tracking_peak_error_urad")
    assert budget["summary"].endswith("u = 18 µrad")
    assert [significant(x) for x in (18.0, 0.005, 180.4, 2.8e-5, 9.96)] == [
        "18", "0.0050", "180", "2.8e-05", "10"]


def test_limits_of_a_size_read_one_sided(elevation_run: Run) -> None:
    rows = {line.split()[-1]: line for line in txt(elevation_run).splitlines()
            if line.rstrip().endswith(("_urad", "_kg_m2", "_pct"))}
    assert "≤ 20 " in rows["cogging_ripple_compensated_urad"]
    assert "-20" not in rows["cogging_ripple_compensated_urad"]
    assert "≤ 2500 " in rows["tracking_rms_error_urad"]
    assert "≤ 5 " in rows["inertia_amplitude_spread_pct"]
    assert "0.00306 to 0.00414" in rows["inertia_kg_m2"]  # two-sided where it is
    assert "-1 to 1" in rows["step_steady_state_error_pct"]  # a signed error keeps both


def test_a_skipped_protocol_is_listed_once_with_its_reason(elevation_run: Run) -> None:
    reason = "skipped: the unit profile has no [protocols.resonance] table"
    for text in (txt(elevation_run), html_text(elevation_run)):
        assert text.count(reason) == 1
        assert "test_resonance[" not in text


@needs_poppler
def test_no_page_holds_a_scrap_of_a_table(elevation_run: Run) -> None:
    """The protocols table and the raw-data list each on one page, whole."""
    cert = certificate(elevation_run)
    pages = pdf_pages(elevation_run.unit_dir / "certificate.pdf")
    # the page with the table's first row also holds the end of its last row
    last = " ".join(list(cert["method"]["protocols"].values())[-1]["messages"][-1].split())
    first = next(page for page in pages if re.search(r"^\s*Protocols\s*$", page, re.MULTILINE))
    assert last[-40:] in " ".join(first.split()), "the protocols table on one page"
    files = [f["file"] for f in cert["raw_data"]]
    assert any(all(f in page for f in files) for page in pages), "the raw data on one page"


def test_the_legends_lie_off_the_data(elevation_run: Run) -> None:
    cert = certificate(elevation_run)
    for data in from_certificate(cert, elevation_run.unit_dir):
        if data.name not in IDENTIFICATION_PLOTS:
            continue
        with styled():
            fig = protocol_figure(data)
            assert fig is not None, data.name
            fig.draw_without_rendering()  # lays the figure out: the extents below are final
            plots = [ax.get_window_extent() for ax in fig.axes]
            legends = [*fig.legends, *(legend for ax in fig.axes
                                       if (legend := ax.get_legend()) is not None)]
            assert legends, data.name
            for legend in legends:
                box = legend.get_window_extent()
                assert not any(box.overlaps(p) for p in plots), f"{data.name}: legend on data"
