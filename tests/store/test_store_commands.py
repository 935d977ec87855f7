"""``gimbal-hil results``: ingest, units, history (as found / as left), trend; tables a
person reads (GUM rounding) and ``--json`` (full precision); bad input is one line, exit 2."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from store_variants import SERIAL

from hil.cli import main
from hil.gum import rounded_pair


def _run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(["results", *args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _certificates(calibrated: Path) -> list[dict[str, object]]:
    """The two real certificates, oldest first."""
    paths = [*sorted((calibrated / SERIAL / "history").glob("*/certificate.json")),
             calibrated / SERIAL / "certificate.json"]
    return [json.loads(p.read_text(encoding="utf-8")) for p in paths]


def test_units_history_and_trend(store_url: str, calibrated: Path,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    store = ["--store", store_url]
    code, out, _ = _run(capsys, "ingest", str(calibrated), *store)
    assert code == 0
    assert "ingest: 2 run(s) stored, 0 already stored" in out
    found, left = _certificates(calibrated)

    code, out, _ = _run(capsys, "units", *store, "--json")
    (unit,) = json.loads(out)
    assert (unit["serial"], unit["runs"], unit["certificate_id"], unit["outcome"]) == (
        SERIAL, 2, left["certificate_id"], "PASS")
    code, out, _ = _run(capsys, "units", *store)
    assert out.splitlines()[2].split()[0] == SERIAL

    code, out, _ = _run(capsys, "history", SERIAL, *store, "--json")
    data = json.loads(out)
    assert [r["certificate_id"] for r in data["runs"]] == [found["certificate_id"],
                                                          left["certificate_id"]]
    rows = {r["name"]: r for r in data["results"]}
    for side, cert in (("as_found", found), ("as_left", left)):
        for result in cert["results"]:  # type: ignore[attr-defined]
            assert rows[result["parameter"]][side]["value"] == result["value"]
    code, out, _ = _run(capsys, "history", SERIAL, *store)
    assert "as found (run 1) → as left (run 2, the latest)" in out
    inertia = {r["parameter"]: r for r in found["results"]}["inertia_kg_m2"]  # type: ignore
    value, u = rounded_pair(inertia["value"], inertia["expanded_uncertainty"])
    line = next(x for x in out.splitlines() if x.startswith("inertia_kg_m2"))
    assert f"{value} ± {u}" in line

    code, out, _ = _run(capsys, "trend", "inertia_kg_m2", *store, "--json")
    trend = json.loads(out)
    assert [p["certificate_id"] for p in trend["points"]] == [
        found["certificate_id"], left["certificate_id"]]
    assert trend["n"] == 2
    code, out, _ = _run(capsys, "trend", "inertia_kg_m2", *store, "--station", "nowhere")
    assert "no runs match" in out
    code, out, _ = _run(capsys, "trend", "inertia_kg_m2", *store, "--since", "2999-01-01")
    assert "no runs match" in out
    code, out, _ = _run(capsys, "trend", "inertia_kg_m2", *store)
    assert f"{value} ± {u}" in out
    assert "mean " in out.splitlines()[-1]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("history", "NO-SUCH-UNIT"), "no runs of unit 'NO-SUCH-UNIT'"),
        (("trend", "inertia_kg_m3"), "no result 'inertia_kg_m3' in"),
        (("trend", "inertia_kg_m2", "--since", "last tuesday"), "--since: not a date"),
        (("units", "--store", "mysql://db/x"), "--store: store must be sqlite:///FILE or"),
        (("ingest", "no/such/dir"), "no/such/dir: not a directory"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(
    args: tuple[str, ...], message: str, calibrated: Path, tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    store = ["--out", str(tmp_path)]
    assert _run(capsys, "ingest", str(calibrated), *store)[0] == 0
    code, out, err = _run(capsys, *args, *store)
    assert code == 2
    assert out == ""
    assert len(err.strip().splitlines()) == 1
    assert message in err


def test_a_bad_store_from_the_environment_is_blamed_on_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("GIMBAL_HIL_STORE", "mysql://db/x")
    code, out, err = _run(capsys, "units", "--out", str(tmp_path))
    assert (code, out) == (2, "")
    assert "error: $GIMBAL_HIL_STORE: store must be sqlite:///FILE or" in err, err
