"""The store knows a gimbal's part number (issue 27): ``--part-number`` (and ``--revision``)
keeps ``spc``, ``trend``, ``export``, ``baseline freeze`` and ``yield`` to the gimbals of one
part number; a result is never pooled across axes, nor across part numbers that share an
axis's unit type, and the refusal names each kind with the options that pick it; a gimbal
passes first time when its first gimbal certificate is PASS, reported beside each kind of
axis's first-pass yield; ``history`` of a gimbal shows each axis's as-found / as-left.

The store is filled through the project's own ingest (``ingest_text``) with variants of one
real certificate, and gimbal certificates naming them: no calibration per gimbal."""

from __future__ import annotations

import json
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import pytest
from store_variants import SERIAL, resealed, variant

from hil.certificate.gimbal_file import GIMBAL_SCHEMA
from hil.cli import main
from hil.store import open_store
from hil.store.ingest import ingest_text

NAME = "inertia_kg_m2"
# (part number, revision, axis) → the inertia its units have: far apart, so that a pooled
# series would show; GMB-3's elevation axis is GMB-2's (the same axis profile, unit type)
INERTIA = {("GMB-2", "azimuth"): 0.0080, ("GMB-2", "elevation"): 0.0036,
           ("GMB-3", "azimuth"): 0.0120, ("GMB-3", "elevation"): 0.0050}
UNIT_TYPE = {("GMB-2", "azimuth"): "GMB-2 azimuth axis",
             ("GMB-2", "elevation"): "GMB-2 elevation axis",
             ("GMB-3", "azimuth"): "GMB-3 azimuth axis",
             ("GMB-3", "elevation"): "GMB-2 elevation axis"}
REVISION = {"GMB-2": "B", "GMB-3": "A"}


class _Line:
    """Certificates ingested in time order (one minute apart)."""

    def __init__(self, store_url: str, text: str) -> None:
        self.store_url, self.text, self.index = store_url, text, 0

    def axis(self, serial: str, part: str | None, axis: str, *, attempt: int,
             fail: bool = False) -> dict[str, Any]:
        """An axis's run of ``serial`` (of a gimbal of ``part``, or a one-axis unit)."""
        cert = json.loads(variant(self.text, serial=serial, index=self.index))
        self.index += 1
        cert["unit"].update(axis=axis, type=UNIT_TYPE[(part or "GMB-2", axis)])
        cert["run"]["attempt"] = attempt
        value = INERTIA[(part or "GMB-2", axis)] * (1 + 1e-3 * self.index)
        for result in cert["results"]:
            if result["parameter"] == NAME:
                result["lower_limit"] = 0.85 * INERTIA[(part or "GMB-2", axis)]
                result["nominal"] = INERTIA[(part or "GMB-2", axis)]
                result["upper_limit"] = 1.15 * INERTIA[(part or "GMB-2", axis)]
                result["value"] = 10 * result["upper_limit"] if fail else value
        sealed = resealed(cert)
        assert (sealed["outcome"] == "FAIL") is fail, sealed["outcome"]
        self._ingest(json.dumps(sealed))
        return sealed

    def gimbal(self, serial: str, part: str, *, attempt: int = 1,
               fail: str | None = None) -> None:
        """Both axes of one gimbal calibration, then its gimbal certificate."""
        axes = [self.axis(serial, part, axis, attempt=attempt, fail=axis == fail)
                for axis in ("azimuth", "elevation")]
        ranks = {"PASS": 0, "MARGINAL": 1}
        issued = datetime.fromisoformat(axes[-1]["dates"]["issued"]) + timedelta(seconds=5)
        self._ingest(json.dumps({
            "schema": GIMBAL_SCHEMA, "certificate_id": f"{serial}-gimbal-{self.index}",
            "gimbal": {"serial": serial, "part_number": part, "revision": REVISION[part]},
            "issued": issued.isoformat(),
            "axes": [{"axis": a["unit"]["axis"], "certificate_id": a["certificate_id"],
                      "outcome": a["outcome"]} for a in axes],
            "outcome": max((a["outcome"] for a in axes), key=lambda o: ranks.get(o, 2))}))

    def _ingest(self, text: str) -> None:
        store = open_store(self.store_url)
        try:
            ingest_text(store, text, source=f"test-{self.index}")
        finally:
            store.close()


@pytest.fixture
def line(store_url: str, calibrated: Path) -> list[str]:
    """Three GMB-2 rev B gimbals (G2-2's elevation failed first, both axes recalibrated),
    two GMB-3 rev A gimbals and a one-axis unit of GMB-2's elevation type; ``--store``."""
    made = _Line(store_url, (calibrated / SERIAL / "certificate.json").read_text("utf-8"))
    made.gimbal("G2-1", "GMB-2")
    made.gimbal("G2-2", "GMB-2", fail="elevation")
    made.gimbal("G3-1", "GMB-3")
    made.gimbal("G2-2", "GMB-2", attempt=2)
    made.gimbal("G2-3", "GMB-2")
    made.axis("ONE-1", None, "elevation", attempt=1)
    made.gimbal("G3-2", "GMB-3")
    return ["--store", store_url]


def _run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(["results", *args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_part_number_picks_its_gimbals_and_axes_are_never_pooled(
    line: list[str], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    exported = tmp_path / "x.csv"
    for command in (["spc", NAME], ["trend", NAME], ["spc", "baseline", "freeze", NAME],
                    ["export", NAME, "--output", str(exported)]):
        code, _, err = _run(capsys, *command, *line)
        assert code == 2, command
        message = err.strip()
        assert "\n" not in message
        assert "5 kinds of unit, which are never pooled" in message
        assert ("part number GMB-3, GMB-2 elevation axis: 2 run(s), --part-number GMB-3 "
                "--axis elevation") in message
        assert ("part number GMB-2, GMB-2 azimuth axis: 4 run(s), --part-number GMB-2 "
                "--axis azimuth") in message
        assert "GMB-2 elevation axis: 1 run(s), --part-number none --axis elevation" in message
        assert not exported.exists()
    # one part number: its two axes are still two kinds
    code, _, err = _run(capsys, "spc", NAME, "--part-number", "GMB-2", *line)
    assert code == 2
    assert "2 kinds of unit" in err
    assert "part number GMB-2, GMB-2 elevation axis: 4 run(s), --axis elevation" in err
    # one axis: the part numbers sharing its unit type are still separate kinds
    code, _, err = _run(capsys, "trend", NAME, "--axis", "elevation", *line)
    assert code == 2
    assert "3 kinds of unit" in err
    assert "--part-number GMB-3;" in err or err.rstrip().endswith("choose one")
    # one axis of one part number: charted alone
    code, out, err = _run(capsys, "spc", NAME, "--part-number", "GMB-3", "--axis",
                          "elevation", "--json", *line)
    assert code in (0, 1), err
    charted = json.loads(out)
    assert charted["n"] == 2
    assert {p["serial"] for p in charted["points"]} == {"G3-1", "G3-2"}
    assert all(p["value"] == pytest.approx(INERTIA[("GMB-3", "elevation")], rel=0.02)
               for p in charted["points"])
    code, out, _ = _run(capsys, "trend", NAME, "--part-number", "GMB-2", "--revision", "B",
                        "--axis", "elevation", "--json", *line)
    assert code == 0
    assert [p["serial"] for p in json.loads(out)["points"]] == ["G2-1", "G2-2", "G2-2",
                                                                 "G2-3"]
    code, out, _ = _run(capsys, "trend", NAME, "--part-number", "none", "--json", *line)
    assert code == 0
    assert [p["serial"] for p in json.loads(out)["points"]] == ["ONE-1"]
    code, _, err = _run(capsys, "export", NAME, "--part-number", "GMB-2", "--axis", "azimuth",
                        "--output", str(exported), *line)
    assert code == 0, err
    assert len(exported.read_text(encoding="utf-8").splitlines()) == 1 + 4
    code, _, err = _run(capsys, "spc", NAME, "--part-number", "GMB-2", "--revision", "A",
                        "--axis", "azimuth", *line)
    assert code == 2
    assert "with --axis azimuth --part-number GMB-2 --revision A" in err
    code, _, err = _run(capsys, "spc", NAME, "--revision", "B", *line)
    assert code == 2
    assert "give --part-number too" in err


def test_a_gimbal_passes_first_time_when_its_first_gimbal_certificate_is_pass(
    line: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = _run(capsys, "yield", "--json", *line)
    assert code == 0
    shown = json.loads(out)
    gimbals = {r["kind"]: (r["units"], r["passed"], r["failed"]) for r in shown["gimbals"]}
    # G2-2's first gimbal certificate FAILed (its elevation); its recalibration does not count
    assert gimbals == {"GMB-2": (3, 2, 1), "GMB-3": (2, 2, 0)}
    axes = {r["kind"]: (r["units"], r["passed"], r["failed"]) for r in shown["axes"]}
    assert axes == {"GMB-2 azimuth": (3, 3, 0), "GMB-2 elevation": (3, 2, 1),
                    "GMB-3 azimuth": (2, 2, 0), "GMB-3 elevation": (2, 2, 0),
                    "GMB-2 elevation axis": (1, 1, 0)}
    (units,) = shown["rows"]
    assert (units["units"], units["passed"], units["failed"]) == (6, 5, 1)
    code, out, _ = _run(capsys, "yield", "--part-number", "GMB-3", "--json", *line)
    shown = json.loads(out)
    assert [(r["kind"], r["units"]) for r in shown["gimbals"]] == [("GMB-3", 2)]
    assert {r["kind"] for r in shown["axes"]} == {"GMB-3 azimuth", "GMB-3 elevation"}
    assert shown["rows"][0]["units"] == 2
    code, out, _ = _run(capsys, "yield", *line)
    assert code == 0
    assert "gimbals (passed first time: the first gimbal certificate PASS" in out
    assert "GMB-2 elevation" in out


def test_history_of_a_gimbal_shows_each_axis_as_found_and_as_left(
    line: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = _run(capsys, "history", "G2-2", *line)
    assert code == 0
    assert "unit G2-2 (GMB-2 rev B): 4 run(s) of 2 axes (azimuth, elevation)" in out
    assert "elevation: as found (run 1) → as left (run 2, the latest):" in out
    assert "azimuth: as found (run 1) → as left (run 2, the latest):" in out
    assert "FAIL → PASS" in out  # the elevation's inertia
    code, out, _ = _run(capsys, "history", "G2-2", "--json", *line)
    shown = json.loads(out)
    assert [g["outcome"] for g in shown["gimbal_certificates"]] == ["FAIL", "PASS"]
    assert [a["axis"] for a in shown["axes"]] == ["azimuth", "elevation"]
    code, out, _ = _run(capsys, "history", "G3-1", *line)
    assert code == 0
    assert "azimuth: no earlier run of this axis (as found -) → as left (run 1" in out
    assert "elevation: no earlier run of this axis (as found -) → as left (run 1" in out
    assert NAME in out
