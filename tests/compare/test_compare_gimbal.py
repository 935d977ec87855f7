"""A gimbal before and after a firmware change: ``compare`` reads two gimbal folders and
pairs each axis's results with the same axis's (never azimuth with elevation: both have
an inertia, a current loop ...); a change on one axis shows on that axis alone."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import tomli_w

from hil.characterise.processes import run_command
from hil.cli import main
from hil.config import builtin_fixture
from tests.compare.firmware_variants import firmware_setting, with_firmware, write_profile

SERIAL = "GMB-C1"


def gimbal(out: Path, *, elevation_tau_scale: float = 1.0) -> Path:
    """A gimbal profile of the demo axes (the elevation's current loop scaled)."""
    tau_s = firmware_setting("demo_gimbal_elevation", "current_loop_time_constant_s")
    elevation = write_profile(
        with_firmware("demo_gimbal_elevation",
                      current_loop_time_constant_s=tau_s * elevation_tau_scale),
        out / "elevation.toml")
    document = {"gimbal": {"part_number": "GMB-2", "revision": "B"},
                "axes": {"azimuth": {"profile": str(builtin_fixture("demo_gimbal_azimuth.toml"))},
                         "elevation": {"profile": str(elevation)}}}
    path = out / "gimbal.toml"
    path.write_text(tomli_w.dumps(document), encoding="utf-8")
    return path


def calibrate(out: Path, *, seed: int, elevation_tau_scale: float = 1.0) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    profile = gimbal(out, elevation_tau_scale=elevation_tau_scale)
    done = run_command(
        ["calibrate", "--gimbal", str(profile), "--drive", "sim", "--unit-serial", SERIAL,
         "--seed", str(seed), "--out", str(out / "units"), "--store", "off", "--",
         "-k", "current_loop", "--no-documents"], timeout_s=600)
    folder = out / "units" / SERIAL
    assert (folder / "gimbal-certificate.json").is_file(), done.stdout + done.stderr
    return folder


@pytest.mark.slow
def test_a_slower_current_loop_on_one_axis_is_worse_on_that_axis_alone(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    baseline = calibrate(tmp_path / "before", seed=1)
    candidate = calibrate(tmp_path / "after", seed=2, elevation_tau_scale=2.0)
    report = tmp_path / "compare.json"
    code = main(["compare", str(baseline), str(candidate), "--json", str(report)])
    rows = json.loads(report.read_text(encoding="utf-8"))["results"]
    verdicts = {(r["serial"], r["parameter"]): r["verdict"] for r in rows}
    assert code == 1, capsys.readouterr().out
    assert set(verdicts) == {(f"{SERIAL}/{axis}", "current_loop_time_constant_ms")
                             for axis in ("azimuth", "elevation")}
    assert verdicts[(f"{SERIAL}/elevation", "current_loop_time_constant_ms")] == "WORSE"
    # INCONCLUSIVE is not a flag (the azimuth's τ has few degrees of freedom)
    assert verdicts[(f"{SERIAL}/azimuth", "current_loop_time_constant_ms")] in (
        "SAME", "INCONCLUSIVE")
    # a gimbal's folder against one axis's certificate: not the same unit
    assert main(["compare", str(baseline),
                 str(candidate / "elevation" / SERIAL / "certificate.json")]) == 2
