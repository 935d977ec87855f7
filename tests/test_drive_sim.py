"""SimDrive and the Drive contract: limits before motion, state rules, always disabled."""

from __future__ import annotations

import _thread
import threading
import time

import numpy as np
import pytest

from hil.drives.base import DriveState, Interrupted
from hil.drives.sim import SimDrive
from hil.errors import DriveStateError, LimitViolationError
from hil.motion import Excitation, Limits, Mode
from plant_sim.firmware import Firmware
from plant_sim.params import PlantParams

LIMITS = Limits(velocity_rad_s=2.0, torque_nm=0.3, travel_min_rad=-1.0, travel_max_rad=1.0)
FS = 1000.0


def _drive() -> SimDrive:
    plant = PlantParams(inertia_kg_m2=0.003, coulomb_nm=0.01)
    firmware = Firmware(velocity_kp_nm_s_rad=0.3, velocity_ki_nm_rad=10.0)
    return SimDrive(plant, firmware=firmware, limits=LIMITS, fs_hz=FS, seed=0)


@pytest.mark.parametrize(
    ("mode", "command", "message"),
    [
        (Mode.VELOCITY, np.full(100, 2.5), "peak velocity"),
        (Mode.TORQUE, np.full(100, -0.31), "peak torque"),
        (Mode.VELOCITY, np.full(1500, 1.0), "travel"),  # 1.5 rad of travel
        (Mode.POSITION, np.linspace(0, 1.2, 5000), "travel"),
        (Mode.POSITION, np.array([0.0, 0.5] * 60), "peak velocity"),  # 500 rad/s jumps
        (Mode.VELOCITY, np.array([0.1, np.nan] * 60), "non-finite"),
    ],
)
def test_commands_outside_the_limits_are_refused_before_any_motion(
    mode: Mode, command: np.ndarray, message: str
) -> None:
    drive = _drive()
    drive.enable()
    before = drive.status().position_rad
    with pytest.raises(LimitViolationError, match=message):
        drive.run(Excitation(name="bad", mode=mode, command=command, fs_hz=FS))
    assert drive.status().position_rad == before
    assert drive.plant.time_s == 0.0


def test_run_needs_an_enabled_drive_and_the_drive_rate() -> None:
    drive = _drive()
    ok = Excitation(name="ok", mode=Mode.VELOCITY, command=np.full(100, 0.1), fs_hz=FS)
    with pytest.raises(DriveStateError, match="disabled"):
        drive.run(ok)
    drive.enable()
    with pytest.raises(DriveStateError, match="Hz"):
        drive.run(Excitation(name="fast", mode=Mode.VELOCITY, command=np.zeros(100), fs_hz=4e3))
    recording = drive.run(ok)
    assert len(recording) == 100
    assert recording.metadata["excitation"] == "ok"


def test_leaving_the_context_disables_even_on_error() -> None:
    drive = _drive()

    def calibrate_and_crash() -> None:
        with drive:
            drive.enable()
            assert drive.status().state is DriveState.ENABLED
            raise RuntimeError("operator pulled the plug")

    with pytest.raises(RuntimeError, match="plug"):
        calibrate_and_crash()
    assert drive.status().state is DriveState.DISABLED
    drive.disable()  # idempotent
    assert drive.status().state is DriveState.DISABLED


def test_position_carries_over_between_runs() -> None:
    drive = _drive()
    drive.enable()
    first = drive.run(Excitation(name="a", mode=Mode.VELOCITY, command=np.full(500, 0.5),
                                 fs_hz=FS))
    second = drive.run(Excitation(name="b", mode=Mode.VELOCITY, command=np.zeros(500), fs_hz=FS))
    assert second.time_s[0] > first.time_s[-1]
    assert second.position[0] == pytest.approx(first.position[-1], abs=1e-3)


def _sine(duration_s: float) -> Excitation:
    t = np.arange(round(duration_s * FS)) / FS
    return Excitation(name="sine", mode=Mode.VELOCITY, command=0.5 * np.sin(2 * np.pi * t),
                      fs_hz=FS)


def test_a_paced_run_keeps_to_the_wall_clock_and_moves_as_an_unpaced_one() -> None:
    """Piece by piece, the plant's state carries over: a noiseless plant's recording is the
    unpaced one to the last bit, and it takes its motion time over the pace."""
    plant = PlantParams(inertia_kg_m2=0.003, coulomb_nm=0.01, viscous_nm_s_rad=0.002)
    firmware = Firmware(velocity_kp_nm_s_rad=0.3, velocity_ki_nm_rad=10.0)
    recordings, took = [], []
    for pace in (None, 4.0):
        drive = SimDrive(plant, firmware=firmware, limits=LIMITS, fs_hz=FS, seed=0, pace=pace)
        drive.enable()
        started = time.monotonic()
        recordings.append(drive.run(_sine(1.2)))
        took.append(time.monotonic() - started)
    unpaced, paced = recordings
    assert unpaced.columns.keys() == paced.columns.keys()
    for name, column in unpaced.columns.items():
        np.testing.assert_array_equal(paced.columns[name], column, err_msg=name)
    assert took[1] >= 1.2 / 4.0


def test_a_stop_mid_paced_motion_quick_stops_and_keeps_the_rows_so_far() -> None:
    drive = SimDrive(PlantParams(inertia_kg_m2=0.003, coulomb_nm=0.01),
                     firmware=Firmware(velocity_kp_nm_s_rad=0.3, velocity_ki_nm_rad=10.0),
                     limits=LIMITS, fs_hz=FS, seed=0, pace=1.0)
    drive.enable()
    timer = threading.Timer(0.3, _thread.interrupt_main)  # SIGINT's KeyboardInterrupt
    timer.start()
    with pytest.raises(Interrupted) as stopped:
        drive.run(_sine(2.0))
    timer.join()
    partial = stopped.value.partial_recording
    assert partial is not None
    assert 0.25 < partial.duration_s < 1.9  # the rows until the stop, not the excitation's
    assert drive.status().state is DriveState.QUICK_STOPPED
    assert abs(drive.status().velocity_rad_s) < 0.05  # braked to rest
