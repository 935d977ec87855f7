"""CANopen object maps (issue 28): each shipped map loads and cites its document, a bad map
or station key is one line, and the whole elevation suite runs over the CiA 402 emulator
presenting itself as each shipped drive model: every protocol measures or says what the
drive lacks, none stops with an error, and J is found within its U of the plant's."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from hil.config import builtin_fixture
from hil.drives.canopen_map import load_object_map, shipped_maps
from hil.drives.station import load_station
from hil.errors import ProfileError
from hil.profile import load_profile
from hil.recording import read_recording

pytestmark = pytest.mark.slow(seconds=55)  # scheduled early (conftest.py)

PROFILE = builtin_fixture("demo_gimbal_elevation.toml")
EMULATOR_STATION = builtin_fixture("station_canopen_emulator.toml")


def test_every_shipped_map_loads_and_cites_its_document() -> None:
    names = shipped_maps()
    assert {"cia402_generic", "gimbal_hil_servo", "maxon_epos4", "estun_ed3s"} <= set(names)
    for name in names:
        loaded = load_object_map(name)
        assert loaded.document.strip()
        assert loaded.position_latch
        assert loaded.torque_reports
    generic = load_object_map("cia402_generic")
    assert generic.objects() == []
    assert not generic.has_recorder
    assert generic.compensation_index is None


@pytest.mark.parametrize(("change", "named"), [
    (("torque_mean = \"absent\"", "torque_maen = \"absent\""), "torque_mean"),
    (("recorder = \"absent\"", "recorder = { index = 0x2200 }"), "recorder"),
    (("type = \"INTEGER16\"", "type = \"INT16\""), "type"),
    (("position_latch = \"unknown\"", "position_latch = \"sometimes\""), "position_latch"),
])
def test_a_bad_map_is_refused_in_one_line(tmp_path: Path, change: tuple[str, str],
                                          named: str) -> None:
    source = "maxon_epos4" if "INTEGER16" in change[0] else "cia402_generic"
    text = (builtin_fixture("canopen_maps") / f"{source}.toml").read_text(encoding="utf-8")
    assert change[0] in text
    bad = tmp_path / "bad_map.toml"
    bad.write_text(text.replace(change[0], change[1], 1), encoding="utf-8")
    with pytest.raises(ProfileError) as refused:
        load_object_map(bad)
    message = str(refused.value)
    assert "\n" not in message
    assert "bad_map.toml" in message
    assert named in message


def test_a_station_naming_an_unknown_map_is_refused_in_one_line(tmp_path: Path) -> None:
    text = EMULATOR_STATION.read_text(encoding="utf-8")
    station = tmp_path / "station.toml"
    station.write_text(text.replace('object_map = "gimbal_hil_servo"',
                                    'object_map = "maxon_epos5"'), encoding="utf-8")
    with pytest.raises(ProfileError) as refused:
        load_station(station)
    message = str(refused.value)
    assert "station.toml" in message
    assert "object_map" in message
    assert "maxon_epos4" in message  # the shipped ones are listed


def test_maps_that_give_the_same_drive_behave_alike() -> None:
    """The emulator's behaviour under a map depends on the map's objects, units and
    conventions alone: a map that gives the same ones as another (the ESTUN ED3S, standard
    objects only, as the generic map) presents the same drive, so the suite over it is the
    suite under that map (run below) and is not run twice."""
    estun, generic = load_object_map("estun_ed3s"), load_object_map("cia402_generic")
    same = ("torque_mean", "control_period", "recorder_index", "waveform_index",
            "compensation_index", "rated_torque_per_nm", "rated_current_per_a",
            "velocity_per_rad_s", "position_latch", "torque_reports", "interpolation_codes",
            "heartbeat_at_power_on")
    assert {k: getattr(estun, k) for k in same} == {k: getattr(generic, k) for k in same}
    assert (estun.name, estun.document) != (generic.name, generic.document)


@pytest.mark.parametrize("map_name", ["cia402_generic", "maxon_epos4"])
def test_the_suite_runs_over_the_emulator_under_each_map(tmp_path: Path, map_name: str) -> None:
    """The emulator's own map runs in every other CANopen test; here the emulator presents
    itself as each other shipped drive model (its objects moved or removed, its units)."""
    text = EMULATOR_STATION.read_text(encoding="utf-8")
    station = tmp_path / "station.toml"
    station.write_text(text.replace('object_map = "gimbal_hil_servo"',
                                    f'object_map = "{map_name}"'), encoding="utf-8")
    done = subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--drive", "canopen-emulator",
         "--station", str(station), "--profile", str(PROFILE), "--out", str(tmp_path),
         "--", "--no-documents", "--store", "off"],
        capture_output=True, text=True, timeout=600, check=False)
    path = tmp_path / "SIM-0001" / "certificate.json"
    assert path.is_file(), done.stdout[-3000:] + done.stderr[-3000:]
    certificate = json.loads(path.read_text(encoding="utf-8"))
    stopped = [m for m in certificate["not_measured"] if not m["reason"].startswith("skipped")]
    assert not stopped, (stopped, done.stdout[-3000:])
    results = {r["parameter"]: r for r in certificate["results"]}
    for measured in ("inertia_kg_m2", "coulomb_nm", "gravity_mge_nm", "static_friction_nm"):
        assert measured in results, sorted(results)
    truth = load_profile(PROFILE).plant
    assert truth is not None
    inertia = results["inertia_kg_m2"]  # in reported-torque units: K_t error of the unit
    reported = truth.inertia_kg_m2 / (1 + truth.torque_constant_error_rel)
    assert abs(inertia["value"] - reported) <= inertia["expanded_uncertainty"]
    recording = read_recording(
        tmp_path / "SIM-0001" / "recordings" / "inertia_friction__sine_2hz_0.5rad_s.csv.gz",
        log_warnings=False)
    assert recording.metadata["object_map"] == load_object_map(map_name).name
    expected_sample = "mean" if load_object_map(map_name).torque_mean is not None else (
        "instantaneous")
    assert recording.metadata["torque_sample"] == expected_sample
