"""A gimbal on one CAN bus: the axis under test streams, the other axis's drive holds it
(profile position) and moves it for real between runs; one SYNC producer, the bus load
checked with every node's heartbeat before any motion."""

from __future__ import annotations

import dataclasses
import json
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from hil.config import builtin_fixture
from hil.drives.base import Capability
from hil.drives.cia402.drive import CanOpenDrive
from hil.drives.cia402.emulator import ENABLED
from hil.drives.emulated import canopen_emulator
from hil.drives.station import CanOpenStation, load_station
from hil.errors import DriveStateError, LimitViolationError, ProfileError
from hil.identify.cross_coupling import fit_cross_coupling
from hil.motion import Excitation, Mode
from hil.profile import load_profile
from hil.suite import cross_coupling
from hil.suite.plan import acquisition_info
from hil.suite.travel import move_excitation
from tests.drives.conftest import sine
from tests.gimbal_truth import InnerGimbal, coupling_passes, plant_changes

pytestmark = pytest.mark.slow(seconds=80)  # scheduled early (conftest.py)

STATION = builtin_fixture("station_canopen_gimbal_emulator.toml")


def _station_file(tmp_path: Path, **canopen: object) -> Path:
    document = tomllib.loads(STATION.read_text(encoding="utf-8"))
    document["canopen"].update(canopen)
    path = tmp_path / "station.toml"
    path.write_text(tomli_w.dumps(document), encoding="utf-8")
    return path


def test_each_axis_is_its_node_and_the_others_are_held() -> None:
    station = load_station(STATION)
    assert isinstance(station, CanOpenStation)
    azimuth, elevation = station.for_axis("azimuth"), station.for_axis("elevation")
    assert (azimuth.node_id, dict(azimuth.held)) == (5, {"elevation": 6})
    assert (elevation.node_id, dict(elevation.held)) == (6, {"azimuth": 5})
    with pytest.raises(ProfileError, match=r"no address for the profile's axis 'roll' "
                                           r"\(it names azimuth, elevation\)") as caught:
        station.for_axis("roll")
    assert str(STATION) in str(caught.value)


@pytest.mark.parametrize(("axes", "message"), [
    ({"azimuth": 5, "elevation": 5}, "two axes one node"),
    ({"azimuth": 5, "elevation": 128}, r"'elevation': is a bus address, 1\.\.127, got 128"),
    ({"azimuth": 5, "elevation": 127}, r"'host_node_id': is node 127 of \[canopen.axes\]"),
    ({"azimuth": 5, "roll": 6}, r"\[canopen.hold.at_rad\] names axis 'elevation', not one "
                                r"of \[canopen.axes\] \(azimuth, roll\)"),
])
def test_a_bus_that_cannot_be_is_refused_at_load(tmp_path: Path, axes: dict[str, int],
                                                 message: str) -> None:
    with pytest.raises(ProfileError, match=message):
        load_station(_station_file(tmp_path, axes=axes))


def test_the_elevation_drive_moves_for_real_and_is_left_disabled() -> None:
    profile = load_profile("demo_gimbal_azimuth")
    station = load_station(STATION)
    assert isinstance(station, CanOpenStation)
    with canopen_emulator(profile, seed=5, base_station=station) as (azimuth, on_bus):
        elevation = azimuth.held_nodes["elevation"]
        with CanOpenDrive(on_bus, limits=profile.limits) as drive:
            assert Capability.ELEVATION_AXIS in drive.info.capabilities
            assert elevation.state == ENABLED  # held from bring-up on
            drive.enable()
            for angle in (0.7, -1.1):
                drive.set_elevation(angle)
                # the elevation node's own plant stands there, and the azimuth's inertia
                # follows it: the coupling goes through the bus, not through a parameter
                assert elevation.plant.position_rad == pytest.approx(angle, abs=0.002)
                assert azimuth.plant.params.elevation_rad == pytest.approx(angle, abs=0.002)
            recording = drive.run(sine(0.3, fs_hz=1000.0, periods=1))
            held = re.fullmatch(r"elevation node 6 at ([-+.0-9]+) rad",
                                recording.metadata["held_axes"])
            assert held is not None
            assert float(held[1]) == pytest.approx(-1.1, abs=0.002)
            assert elevation.plant.position_rad == pytest.approx(-1.1, abs=0.002)
        assert elevation.state != ENABLED
        assert azimuth.state != ENABLED


def test_after_a_run_on_the_drive_recorder_the_axis_holds_where_it_ended() -> None:
    """The SYNC stream goes on while a held axis moves: the target it carries must be where
    the recorder's run ended (a stale one pulled the azimuth back from 1.89 rad until it
    stopped at its own limit, and the next run was refused)."""
    profile = load_profile("demo_gimbal_azimuth")
    station = load_station(STATION)
    assert isinstance(station, CanOpenStation)
    station = dataclasses.replace(station, acquisition="auto")
    with canopen_emulator(profile, seed=5, base_station=station) as (azimuth, on_bus), \
            CanOpenDrive(on_bus, limits=profile.limits) as drive:
        drive.enable()
        fs = drive.info.max_sample_rate_hz
        assert fs > 1000.0  # the recorder's rate: the move runs on it
        drive.run(move_excitation("move", drive.status().position_rad, 1.89, fs_hz=fs,
                                  speed_rad_s=2.0, hold_s=0.2))
        drive.set_elevation(0.6)
        assert azimuth.state == ENABLED
        assert drive.status().position_rad == pytest.approx(1.89, abs=0.002)
        drive.run(sine(0.3, fs_hz=fs, periods=1))


def test_a_bus_load_beyond_the_budget_is_refused_before_motion() -> None:
    profile = load_profile("demo_gimbal_azimuth")
    station = load_station(STATION)
    assert isinstance(station, CanOpenStation)
    with canopen_emulator(profile, seed=6, base_station=station,
                          station_changes={"max_bus_load": 0.4}) as (azimuth, on_bus):
        with pytest.raises(DriveStateError, match=r"SYNC at 1000 Hz with 1 held axis node\(s\) "
                                                  r"needs 45% of a 1000 kbit/s bus, more than "
                                                  r"the station's max_bus_load 40%"):
            CanOpenDrive(on_bus, limits=profile.limits)
        assert azimuth.sync_count == 0
        assert azimuth.held_nodes["elevation"].sync_count == 0


@pytest.mark.slow
def test_a_hidden_product_of_inertia_is_found_over_the_bus(tmp_path: Path) -> None:
    """The azimuth plant's elevation stage drawn here (not the profile's P or ΔJ), the
    elevation drive moved for real over CANopen: P within its stated U."""
    rng = np.random.default_rng(20261128)
    product = float(rng.choice([-1.0, 1.0]) * rng.uniform(1e-4, 5e-4))
    delta = float(rng.uniform(1e-3, 2e-3))
    document = tomllib.loads(builtin_fixture("demo_gimbal_azimuth.toml").read_text("utf-8"))
    document["plant"].update(inertia_product_kg_m2=product, inertia_elevation_kg_m2=delta)
    profile = tmp_path / "azimuth.toml"
    profile.write_text(tomli_w.dumps(document), encoding="utf-8")
    station = tmp_path / "station.toml"
    station_document = tomllib.loads(STATION.read_text(encoding="utf-8"))
    station_document["canopen"]["emulated_profiles"]["azimuth"] = str(profile)
    station.write_text(tomli_w.dumps(station_document), encoding="utf-8")
    done = subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--drive", "canopen-emulator",
         "--station", str(station), "--profile", str(profile), "--unit-serial", "GMB-H1",
         "--seed", "3", "--out", str(tmp_path), "--", "-k", "inertia_elevation",
         "--no-documents", "--store", "off"],
        capture_output=True, text=True, timeout=600, check=False)
    certificate = tmp_path / "GMB-H1" / "certificate.json"
    assert certificate.is_file(), done.stdout + done.stderr
    document = json.loads(certificate.read_text("utf-8"))
    results = {r["parameter"]: r for r in document["results"]}
    found = results["azimuth_inertia_product_kg_m2"]
    assert abs(found["value"] - product) <= found["expanded_uncertainty"], (found, product)
    # and resolved: an interval as wide as P itself would hold any truth near it
    assert found["expanded_uncertainty"] < 0.5 * abs(product), (found, product)
    # the certificate states where the elevation stood for each sine (read from its drive)
    sines = [f for f in document["raw_data"] if "_el" in f["excitation"]]
    assert len(sines) == 8
    for entry in sines:
        commanded = float(re.search(r"_el([-+.0-9]+)rad", entry["excitation"])[1])  # type: ignore[index]
        held = re.fullmatch(r"elevation node 6 at ([-+.0-9]+) rad", entry["held_axes"])
        assert held is not None
        assert float(held[1]) == pytest.approx(commanded, abs=0.003)


def test_hidden_products_of_inertia_are_found_over_the_bus(tmp_path: Path) -> None:
    """The emulated gimbal is one coupled plant (both nodes stepped together at each SYNC):
    an inner gimbal drawn here (an imbalance mass and the payload's own products, as the
    simulator's Hypothesis test draws them) hides the elevation axis's products of inertia;
    the elevation drive follows the swing on its own recorder, started on the SYNC the
    azimuth's starts on, and the cross-coupling passes find both products within their U."""
    rng = np.random.default_rng(20261129)
    inner = InnerGimbal(
        mass_kg=float(rng.uniform(0.05, 0.4)),
        at_m=(float(rng.uniform(-0.02, 0.02)), float(rng.choice([-1, 1]) * rng.uniform(0.02, 0.05)),
              float(rng.uniform(-0.02, 0.02))),
        own_xy=float(rng.uniform(-2e-4, 2e-4)), own_yz=float(rng.uniform(-2e-4, 2e-4)))
    documents = {axis: tomllib.loads(builtin_fixture(f"demo_gimbal_{axis}.toml")
                                     .read_text("utf-8")) for axis in ("azimuth", "elevation")}
    plants = {axis: load_profile(f"demo_gimbal_{axis}").plant for axis in documents}
    assert plants["azimuth"] is not None
    assert plants["elevation"] is not None
    changes = plant_changes(inner, azimuth=plants["azimuth"], elevation=plants["elevation"])
    station_document = tomllib.loads(STATION.read_text(encoding="utf-8"))
    for (axis, document), changed in zip(documents.items(), changes, strict=True):
        document["plant"].update(changed)
        path = tmp_path / f"{axis}.toml"
        path.write_text(tomli_w.dumps(document), encoding="utf-8")
        station_document["canopen"]["emulated_profiles"][axis] = str(path)
    station_path = tmp_path / "station.toml"
    station_path.write_text(tomli_w.dumps(station_document), encoding="utf-8")
    # three steady periods a pass, not the profile's five: a test of ~30 s
    azimuth = dataclasses.replace(
        load_profile(tmp_path / "azimuth.toml"),
        protocols={**documents["azimuth"]["protocols"],
                   "cross_coupling": {**documents["azimuth"]["protocols"]["cross_coupling"],
                                      "periods": 3}})
    station = load_station(station_path)
    assert isinstance(station, CanOpenStation)
    with canopen_emulator(azimuth, seed=7, base_station=station) as (emulator, on_bus):
        elevation = emulator.held_nodes["elevation"]
        with CanOpenDrive(on_bus, limits=azimuth.limits) as drive:
            assert Capability.ELEVATION_MOTION in drive.info.capabilities
            seen, _ = acquisition_info(cross_coupling.NAME, azimuth, drive.info)
            spec = cross_coupling.Spec.from_profile(azimuth, seen)
            assert seen.recorder is not None  # on both drive recorders, 2 kHz
            drive.enable()
            passes = coupling_passes(drive, spec)
        assert elevation.state != ENABLED
        assert emulator.state != ENABLED
    for name, recording in passes.items():
        # the elevation followed its path, a row per azimuth row (its position loop lags a
        # swing of 2.5 rad/s peak by about 0.08 rad: the fit uses where it was)
        path = next(e for e in cross_coupling.motion(spec, position=lambda: 0.0)
                    if e.name == name).elevation_path_rad
        assert path is not None
        assert len(recording.columns["elevation_rad"]) == len(path)
        lag = np.abs(recording.columns["elevation_rad"] - path)
        assert lag.max() < 0.25 * spec.amplitude_rad, (name, lag.max())
    assert azimuth.plant is not None
    gain = 1.0 + azimuth.plant.torque_constant_error_rel  # reported torque, nominal K_t
    found = fit_cross_coupling(cross_coupling.coupling_runs(spec, passes),
                               azimuth_inertia_kg_m2=1.03 * azimuth.plant.total_inertia_kg_m2
                               / gain)
    for estimate, truth in ((found.level, inner.level), (found.vertical, inner.vertical)):
        assert abs(estimate.value - truth / gain) <= estimate.expanded_uncertainty, (
            estimate, truth / gain)
        # resolved: U within 5 % of the ±0.0006 kg·m² balance limits (three periods a pass
        # give √(5/3) the simulator test's U and fewer degrees of freedom)
        assert estimate.expanded_uncertainty < 3e-5, estimate


def test_an_elevation_path_the_bus_cannot_play_is_refused_before_motion() -> None:
    """A path plays on the elevation's recorder beside a recorder run of the azimuth: a
    streamed run with one is refused, as is a path outside the elevation drive's own
    software position limits (0x607D); a station that streams everything has no
    elevation motion at all. Nothing moves."""
    profile = load_profile("demo_gimbal_azimuth")
    station = load_station(STATION)
    assert isinstance(station, CanOpenStation)

    def swing(fs_hz: float, amplitude_rad: float) -> Excitation:
        n = round(0.5 * fs_hz)
        return Excitation(name="swinging_forward", mode=Mode.VELOCITY, fs_hz=fs_hz,
                          command=np.full(n, 0.1),
                          elevation_path_rad=amplitude_rad * np.sin(np.linspace(0, 3, n)))

    with canopen_emulator(profile, seed=8, base_station=station) as (emulator, on_bus), \
            CanOpenDrive(on_bus, limits=profile.limits) as drive:
        drive.enable()
        elevation = emulator.held_nodes["elevation"]
        before = (drive.status().position_rad, elevation.plant.position_rad)
        with pytest.raises(DriveStateError, match=r"at 1000 Hz would be streamed: the "
                                                  r"elevation follows its path on its own "
                                                  r"drive recorder"):
            drive.run(swing(1000.0, 0.3))
        held = drive.held.axes["elevation"]
        held.write(0x607D, 2, round(0.2 * held.counts_per_rad))
        with pytest.raises(LimitViolationError, match=r"node 6 \(elevation axis\): the path "
                                                      r"spans \[\+0\.0000, \+0\.3000\] rad, "
                                                      r"outside its drive's software position "
                                                      r"limits \(0x607D\)"):
            drive.run(swing(2000.0, 0.3))
        assert (drive.status().position_rad, elevation.plant.position_rad) == pytest.approx(
            before, abs=1e-4)
    streaming = dataclasses.replace(station, acquisition="stream")
    with canopen_emulator(profile, seed=8, base_station=streaming) as (_, on_bus), \
            CanOpenDrive(on_bus, limits=profile.limits) as drive:
        assert Capability.ELEVATION_MOTION not in drive.info.capabilities
        drive.enable()
        with pytest.raises(DriveStateError, match=r"lacks: elevation axis that follows a path"):
            drive.run(swing(1000.0, 0.3))
