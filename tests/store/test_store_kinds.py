"""A result stored for two kinds of unit (a gimbal's azimuth and elevation axes share
``inertia_kg_m2``) is never pooled: ``spc``, ``trend``, ``export`` and ``baseline freeze``
are refused in one line naming the kinds until ``--axis`` or ``--unit-type`` picks one,
which then charts that kind alone; the fleet report has a section per kind; baselines are
frozen per kind (issue 27)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from sqlalchemy import delete
from store_variants import SERIAL, resealed, variant, with_value

from hil.cli import main
from hil.store import load_baseline, open_store, save_baseline
from hil.store.schema import spc_baselines

NAME = "inertia_kg_m2"
AZIMUTH = 0.0080  # the two axes' nominal inertia, far apart: a pooled chart would mix them
ELEVATION = 0.0036


def _ingest(text: str, tmp: Path, index: int, *, axis: str, value: float,
            store: list[str]) -> None:
    path = with_value(text, name=NAME, value=value, serial=f"KND-{index:04d}", index=index,
                      folder=tmp, axis=axis, type=f"GMB-2 {axis} axis")
    assert main(["results", "ingest", str(path), *store]) == 0


@pytest.fixture
def two_axes(store_url: str, calibrated: Path, tmp_path: Path) -> list[str]:
    """26 azimuth runs (a baseline needs 25) and four elevation runs between them, in a
    fresh store; its ``--store`` option."""
    store = ["--store", store_url]
    text = (calibrated / SERIAL / "certificate.json").read_text(encoding="utf-8")
    for i in range(30):
        azimuth = i % 7 != 3
        _ingest(text, tmp_path, i, axis="azimuth" if azimuth else "elevation",
                value=(AZIMUTH if azimuth else ELEVATION) * (1 + 1e-4 * i), store=store)
    return store


def _run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(["results", *args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_a_result_of_two_axes_is_refused_until_one_is_chosen(
    two_axes: list[str], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    for command in (["spc", NAME], ["trend", NAME], ["spc", "baseline", "freeze", NAME],
                    ["export", NAME, "--output", str(tmp_path / "x.csv")]):
        code, out, err = _run(capsys, *command, *two_axes)
        assert code == 2, command
        message = err.strip()
        assert "\n" not in message
        assert "2 kinds of unit, which are never pooled" in message
        assert "GMB-2 azimuth axis: 26 run(s), --axis azimuth" in message
        assert "GMB-2 elevation axis: 4 run(s), --axis elevation" in message
        assert not (tmp_path / "x.csv").exists()
    code, out, _ = _run(capsys, "spc", NAME, "--axis", "elevation", "--json", *two_axes)
    assert code in (0, 1)
    charted = json.loads(out)
    assert charted["n"] == 4
    assert all(p["value"] == pytest.approx(ELEVATION, rel=0.01) for p in charted["points"])
    code, out, _ = _run(capsys, "trend", NAME, "--unit-type", "GMB-2 azimuth axis", "--json",
                        *two_axes)
    assert code == 0
    assert json.loads(out)["n"] == 26
    code, _, err = _run(capsys, "spc", NAME, "--axis", "roll", *two_axes)
    assert code == 2
    assert f"no stored results named '{NAME}' with --axis roll" in err


def test_baselines_are_frozen_per_kind_and_the_report_has_a_section_per_kind(
    two_axes: list[str], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code, out, err = _run(capsys, "spc", "baseline", "freeze", NAME, "--axis", "azimuth",
                          *two_axes)
    assert code == 0, err
    assert "(GMB-2 azimuth axis) frozen from 26 runs" in out
    code, out, _ = _run(capsys, "spc", NAME, "--axis", "azimuth", "--json", *two_axes)
    assert json.loads(out)["baseline"]["n"] == 26
    code, out, _ = _run(capsys, "spc", NAME, "--axis", "elevation", "--json", *two_axes)
    assert json.loads(out)["baseline"] is None  # azimuth's baseline is not elevation's
    page = tmp_path / "fleet.html"
    code, _, _ = _run(capsys, "report", "--html", str(page), "--parameters", NAME, *two_axes)
    assert code == 0
    html = page.read_text(encoding="utf-8")
    assert f"{NAME} (GMB-2 azimuth axis)" in html
    assert f"{NAME} (GMB-2 elevation axis)" in html


def test_a_baseline_frozen_before_kinds_serves_while_the_store_holds_one_kind(
    store_url: str, calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A baseline an older release froze as ``spc:NAME`` charts the one kind the store
    holds; once a second kind is stored it is nobody's (which kind it was is unknown)."""
    store = ["--store", store_url]
    text = (calibrated / SERIAL / "certificate.json").read_text(encoding="utf-8")
    for i in range(25):
        _ingest(text, tmp_path, i, axis="elevation", value=ELEVATION * (1 + 1e-4 * i),
                store=store)
    assert _run(capsys, "spc", "baseline", "freeze", NAME, *store)[0] == 0
    opened = open_store(store_url)  # the baseline moved to the key an older release used
    try:
        key = f"spc:GMB-2 elevation axis/elevation:{NAME}"
        body = load_baseline(opened, key)
        assert body is not None
        save_baseline(opened, f"spc:{NAME}", body)
        with opened.engine.begin() as connection:
            connection.execute(delete(spc_baselines).where(spc_baselines.c.name == key))
    finally:
        opened.close()
    _, out, _ = _run(capsys, "spc", NAME, "--json", *store)
    assert json.loads(out)["baseline"]["n"] == 25
    _ingest(text, tmp_path, 30, axis="azimuth", value=AZIMUTH, store=store)
    _, out, _ = _run(capsys, "spc", NAME, "--axis", "elevation", "--json", *store)
    assert json.loads(out)["baseline"] is None


def test_a_gimbal_serial_passes_first_time_only_when_each_axis_did(
    store_url: str, calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two gimbals, each an azimuth and an elevation run under one serial (attempt 1 each):
    the one whose elevation failed is a failed first pass (it never lowered the yield when
    the lowest attempt of the serial alone counted); ``history`` compares each axis with
    its own earlier run, and shows each axis's results as left when it has none."""
    store = ["--store", store_url]
    text = (calibrated / SERIAL / "certificate.json").read_text(encoding="utf-8")
    index = 0
    for serial, elevation_outcome in (("GMB-0001", "PASS"), ("GMB-0002", "FAIL")):
        for axis in ("azimuth", "elevation"):
            cert = json.loads(variant(text, serial=serial, index=index))
            index += 1
            cert["unit"].update(axis=axis, type=f"GMB-2 {axis} axis")
            cert["run"]["attempt"] = 1
            path = tmp_path / f"g{index}" / "certificate.json"
            path.parent.mkdir(parents=True)
            sealed = resealed(cert)
            if axis == "elevation" and elevation_outcome == "FAIL":
                for result in cert["results"]:
                    if result["parameter"] == NAME:
                        result["value"] = 10 * result["upper_limit"]
                sealed = resealed(cert)
                assert sealed["outcome"] == "FAIL"
            path.write_text(json.dumps(sealed), encoding="utf-8")
            assert main(["results", "ingest", str(path), *store]) == 0
    code, out, _ = _run(capsys, "yield", "--json", *store)
    assert code == 0
    (row,) = json.loads(out)["rows"]
    assert (row["units"], row["passed"], row["failed"]) == (2, 1, 1)
    code, out, _ = _run(capsys, "history", "GMB-0002", "--json", *store)
    assert code == 0
    shown = json.loads(out)
    assert [a["axis"] for a in shown["axes"]] == ["azimuth", "elevation"]
    assert all(a["as_found_run"] is None for a in shown["axes"])  # one run of each axis
    code, out, _ = _run(capsys, "history", "GMB-0002", *store)
    assert "2 run(s) of 2 axes (azimuth, elevation)" in out
    # each axis's results as left, with no earlier run to have been found (issue 27)
    assert "azimuth: no earlier run of this axis (as found -) → as left (run 1" in out
    assert "elevation: no earlier run of this axis (as found -) → as left (run 1" in out
