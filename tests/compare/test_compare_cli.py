"""``gimbal-hil compare`` on hand-made certificates: verdicts, exit codes, refusals, outputs."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from hil.cli import main
from tests.compare.certificate_factory import certificate, result, write

Run = tuple[int, str, str]


def compare(capsys: pytest.CaptureFixture[str], *args: str | Path) -> Run:
    code = main(["compare", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def sides(tmp_path: Path, baseline: dict[str, Any], candidate: dict[str, Any]
          ) -> tuple[Path, Path]:
    return (write(tmp_path / "base" / "U-1" / "certificate.json", baseline),
            write(tmp_path / "cand" / "U-1" / "certificate.json", candidate))


def verdicts(path: Path) -> dict[str, str]:
    return {r["parameter"]: r["verdict"] for r in json.loads(path.read_text())["results"]}


def test_identical_runs_exit_0_and_print_the_rules(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    b, c = sides(tmp_path, certificate(), certificate())
    code, out, err = compare(capsys, b, c, "--json", tmp_path / "o.json")
    assert code == 0, out + err
    assert verdicts(tmp_path / "o.json") == {"coulomb_nm": "SAME", "bandwidth_hz": "SAME"}
    assert "Budget of the difference" in out
    assert "Holm" in out
    assert "Nothing flagged (exit 0)" in out


@pytest.mark.parametrize(("value", "direction", "verdict", "code"), [
    (1.1, "higher", "BETTER", 0),
    (0.9, "higher", "WORSE", 1),
    (0.9, "lower", "BETTER", 0),
    (1.1, "lower", "WORSE", 1),
    (1.1, None, "CHANGED", 1),
])
def test_a_significant_difference_is_judged_by_its_direction(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], value: float, direction: str | None,
    verdict: str, code: int,
) -> None:
    b, c = sides(tmp_path, certificate(results=[result("x", 1.0, u_a=0.01, direction=direction)]),
                 certificate(results=[result("x", value, u_a=0.01, direction=direction)]))
    assert compare(capsys, b, c, "--json", tmp_path / "o.json")[0] == code
    assert verdicts(tmp_path / "o.json") == {"x": verdict}


def test_a_wide_difference_interval_is_inconclusive(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    # tolerance band 0–2: a quarter is 0.5; u(Δ) = 0.3·√2 hides a change that size
    b, c = sides(tmp_path,
                 certificate(results=[result("x", 1.0, u_a=0.3, direction="higher")]),
                 certificate(results=[result("x", 1.1, u_a=0.3, direction="higher")]))
    assert compare(capsys, b, c, "--json", tmp_path / "o.json")[0] == 0
    assert verdicts(tmp_path / "o.json") == {"x": "INCONCLUSIVE"}


def test_holm_keeps_a_borderline_result_among_many_from_being_flagged(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # t = 2.5 (p ≈ 0.012, significant alone) among 20 results: Holm needs p ≤ 0.0025
    same = [result(f"r{i}", 1.0, u_a=0.01, dof_a=None) for i in range(19)]
    u = 0.01
    b, c = sides(tmp_path, certificate(results=[*same, result("x", 1.0, u_a=u, dof_a=None)]),
                 certificate(results=[*same, result("x", 1.0 + 2.5 * u * 2**0.5, u_a=u,
                                                    dof_a=None)]))
    code, _, _ = compare(capsys, b, c, "--json", tmp_path / "o.json")
    row = next(r for r in json.loads((tmp_path / "o.json").read_text())["results"]
               if r["parameter"] == "x")
    assert row["p_value"] == pytest.approx(0.0124, abs=1e-3)
    assert row["p_holm"] == pytest.approx(20 * row["p_value"])
    assert (code, row["verdict"]) == (0, "SAME")


def test_missing_and_new_results(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    b, c = sides(tmp_path, certificate(results=[result("x", 1.0, u_a=0.01)]),
                 certificate(results=[result("y", 1.0, u_a=0.01)]))
    assert compare(capsys, b, c, "--json", tmp_path / "o.json")[0] == 1
    assert verdicts(tmp_path / "o.json") == {"x": "MISSING", "y": "NEW"}


def test_directories_pair_by_serial(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for side, value in (("base", 1.0), ("cand", 1.5)):
        for serial in ("A-1", "A-2"):
            write(tmp_path / side / serial / "certificate.json",
                  certificate(serial, [result("x", value if serial == "A-2" else 1.0,
                                              u_a=0.01)]))
    code, out, _ = compare(capsys, tmp_path / "base", tmp_path / "cand",
                           "--markdown", tmp_path / "o.md")
    assert code == 1
    assert "2 results of 2 unit(s)" in out
    markdown = (tmp_path / "o.md").read_text()
    assert "| A-2 | x |" in markdown
    assert "CHANGED" in markdown


def test_unpaired_serials_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write(tmp_path / "base" / "A-1" / "certificate.json", certificate("A-1"))
    write(tmp_path / "base" / "A-2" / "certificate.json", certificate("A-2"))
    write(tmp_path / "cand" / "A-1" / "certificate.json", certificate("A-1"))
    write(tmp_path / "cand" / "A-3" / "certificate.json", certificate("A-3"))
    code, _, err = compare(capsys, tmp_path / "base", tmp_path / "cand")
    assert code == 2
    assert "A-2 only in the baseline, A-3 only in the candidate" in err


@pytest.mark.parametrize(("candidate", "message"), [
    (certificate("U-2"), "different units: baseline U-1"),
    ({**certificate(), "method": {**certificate()["method"],
                                  "profile_sha256_without_firmware": "e" * 64}},
     "different profiles (profile SHA-256 without its firmware settings"),
])
def test_different_units_or_profiles_are_refused_unless_allowed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], candidate: dict[str, Any], message: str
) -> None:
    b = write(tmp_path / "b.json", certificate())
    c = write(tmp_path / "c.json", candidate)
    code, out, err = compare(capsys, b, c)
    assert (code, out) == (2, "")
    assert message in err
    assert len(err.strip().splitlines()) == 1
    assert "Traceback" not in err
    code, out, _ = compare(capsys, b, c, "--allow-different-units")
    assert code == 0, out


def test_profiles_differing_only_in_firmware_are_compared(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    b, c = sides(tmp_path, certificate(profile_sha="1" * 64), certificate(profile_sha="2" * 64))
    assert compare(capsys, b, c)[0] == 0


def test_station_and_software_differences_warn(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    b, c = sides(tmp_path, certificate(),
                 certificate(version="0.2.0", transport="socketcan"))
    code, _, err = compare(capsys, b, c)
    assert code == 0
    assert "station differs (transport 'in-process' → 'socketcan')" in err
    assert "software differs (gimbal-hil 0.1.0 abc → 0.2.0 abc)" in err


def _broken(document: dict[str, Any]) -> dict[str, Any]:
    document["results"][0]["budget"][0]["standard_uncertainty"] = "small"
    return document


@pytest.mark.parametrize(("content", "message"), [
    (None, "no such file or directory"),
    ("{not json", "not JSON"),
    (json.dumps({**certificate(), "schema": "other/v9"}),
     "not a gimbal-hil certificate (schema 'other/v9')"),
    (json.dumps({k: v for k, v in certificate().items() if k != "results"}),
     "results is missing"),
    (json.dumps(_broken(certificate())),
     "results[0].budget[0].standard_uncertainty must be a number, not a string"),
    (json.dumps(certificate(results=[replace(result("x", 1.0, u_a=0.1), direction="up")])),
     "results[0].direction is 'up', expected 'higher' or 'lower'"),
])
def test_bad_input_is_one_line_naming_what_and_where(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str | None, message: str
) -> None:
    good = write(tmp_path / "good.json", certificate())
    bad = tmp_path / "bad.json"
    if content is not None:
        bad.write_text(content, encoding="utf-8")
    code, out, err = compare(capsys, good, bad)
    assert (code, out) == (2, "")
    assert err.startswith("gimbal-hil: error: ")
    assert str(bad) in err
    assert message in err
    assert len(err.strip().splitlines()) == 1


def test_a_directory_without_certificates_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good = write(tmp_path / "good.json", certificate())
    (tmp_path / "empty").mkdir()
    code, _, err = compare(capsys, good, tmp_path / "empty")
    assert code == 2
    assert "no certificate.json here" in err


def test_alpha_outside_zero_one_is_refused(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    b, c = sides(tmp_path, certificate(), certificate())
    code, _, err = compare(capsys, b, c, "--alpha", "1.5")
    assert code == 2
    assert "--alpha 1.5 must lie between 0 and 1" in err


def test_json_keeps_full_precision_and_text_rounds(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    b, c = sides(tmp_path, certificate(results=[result("x", 1.0123456789, u_a=0.0012345)]),
                 certificate(results=[result("x", 1.0123456789, u_a=0.0012345)]))
    _, out, _ = compare(capsys, b, c, "--json", tmp_path / "o.json")
    row = json.loads((tmp_path / "o.json").read_text())["results"][0]
    assert row["baseline"]["value"] == 1.0123456789
    assert "1.0123 ± 0.0025 N·m" in out


def test_a_repeatability_map_widens_only_its_results(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # coulomb_nm has an entry for the elevation axis: u(Δ) grows; bandwidth_hz has none
    b, c = sides(tmp_path, certificate(), certificate())
    entries = tmp_path / "map.toml"
    entries.write_text('population = "x"\n[results.elevation.coulomb_nm]\nscale = "relative"\n'
                       'scatter = 0.003\npairs = 20\n', encoding="utf-8")
    compare(capsys, b, c, "--json", tmp_path / "with.json", "--repeatability", entries)
    compare(capsys, b, c, "--json", tmp_path / "without.json", "--repeatability", "off")
    def u(name: str) -> dict[str, float]:
        rows = json.loads((tmp_path / name).read_text())["results"]
        return {r["parameter"]: r["budget_of_difference"]["standard_uncertainty"] for r in rows}
    assert u("with.json")["coulomb_nm"] > u("without.json")["coulomb_nm"]
    assert u("with.json")["bandwidth_hz"] == u("without.json")["bandwidth_hz"]


def test_a_bad_repeatability_map_names_file_and_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    b, c = sides(tmp_path, certificate(), certificate())
    bad = tmp_path / "map.toml"
    bad.write_text('population = "x"\n[results.elevation.coulomb_nm]\nscale = "relative"\n'
                   'scatter = -1\npairs = 20\n', encoding="utf-8")
    code, _, err = compare(capsys, b, c, "--repeatability", bad)
    assert code == 2
    assert str(bad) in err
    assert "scatter" in err
