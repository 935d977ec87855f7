"""Diagnose → extended profile (TOML) → simulate → the residual shrinks on held-out data."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest
from diagnose_simdata import FS_HZ, plant, record

from hil.diagnose import cli
from hil.diagnose.core import diagnose
from hil.diagnose.profile_out import data_fields, model_fields, split_firmware, write_profile
from hil.identify.kinematics import zero_phase_lowpass
from hil.motion import Mode
from hil.profile import load_profile
from plant_sim.firmware import Firmware
from plant_sim.model import simulate
from plant_sim.params import plant_from_mapping


def _lowpass(values: np.ndarray) -> np.ndarray:
    return zero_phase_lowpass(values, fs_hz=FS_HZ, cutoff_hz=100.0, segments=((0, len(values)),))


def test_extended_profile_simulates_the_heldout_run_better(tmp_path: Path) -> None:
    hidden = plant(0.004, 0.005, 0.02, "gravity", 0.7, 0.3, 0)
    diagnosis = diagnose(record(hidden.params, seed=11))
    assert diagnosis.cause_names == ["gravity"]
    path = write_profile(diagnosis, tmp_path / "extended.toml")
    profile = load_profile(path)  # what `gimbal-hil simulate --profile` reads
    assert profile.plant is not None
    assert profile.plant.gravity_mge_nm > 0
    base_fields, base_firmware = split_firmware(model_fields(diagnosis.base)
                                                | data_fields(diagnosis))
    base_plant = plant_from_mapping(base_fields)
    firmware = {"base": Firmware(**base_firmware), "extended": profile.firmware}
    heldout = record(hidden.params, seed=12, scale=0.8)  # another run, never diagnosed
    command = heldout.velocity_cmd
    assert command is not None
    measured = _lowpass(heldout.effort)
    errors = {}
    for name, params in (("base", base_plant), ("extended", profile.plant)):
        simulated = simulate(params, mode=Mode.VELOCITY, command=command, fs_hz=FS_HZ, seed=3,
                             firmware=firmware[name])
        errors[name] = float(np.sqrt(np.mean((measured - _lowpass(simulated.effort)) ** 2)))
    assert errors["extended"] < 0.5 * errors["base"], errors


def test_cli_writes_report_plots_and_profile(tmp_path: Path) -> None:
    from hil.recording import write_recording

    hidden = plant(0.004, 0.005, 0.02, "offset", 0.5, 0.9, 0)
    rec = tmp_path / "rec.csv.gz"
    write_recording(record(hidden.params, seed=5), rec)
    parser = argparse.ArgumentParser()
    cli.add_arguments(parser)
    args = parser.parse_args([str(rec), "--json", str(tmp_path / "out.json"),
                              "--plots", str(tmp_path / "plots"),
                              "--profile-out", str(tmp_path / "ext.toml")])
    assert cli.run(args) == 0
    import json

    data = json.loads((tmp_path / "out.json").read_text())
    assert {"base", "residual_tests", "data_issues", "causes"} <= set(data)
    assert data["causes"][0]["name"] == "offset"
    assert set(data["causes"][0]["gain"]) >= {"rms_before_nm", "rms_after_nm", "fit_before_pct",
                                              "fit_after_pct", "delta_bic"}
    assert data["residual_tests"]["ljung_box"]["lags"] == 25
    assert len(list((tmp_path / "plots").glob("*.png"))) == 5
    assert load_profile(tmp_path / "ext.toml").plant is not None


@pytest.mark.parametrize("content", ["time_s,position_rad\n1,2\n", "not a csv"])
def test_cli_bad_file_exits_2(tmp_path: Path, content: str,
                              capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text(content)
    parser = argparse.ArgumentParser()
    cli.add_arguments(parser)
    assert cli.run(parser.parse_args([str(bad), "--json", str(tmp_path / "o.json")])) == 2
    err = capsys.readouterr().err
    assert "bad.csv" in err
    assert "Traceback" not in err
