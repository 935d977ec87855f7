"""Shared protocol motion planning: the envelope and the travel a protocol may ask for."""

from __future__ import annotations

import numpy as np
import pytest

from hil.errors import IdentificationError, ProfileError
from hil.motion import Excitation, Mode
from hil.recording import Recording
from hil.suite.travel import TravelSpec, on_command_grid, speed_ramp

SPEC = TravelSpec(fs_hz=1000.0, travel_min_rad=-1.0, travel_max_rad=1.0, margin_rad=0.1,
                  move_speed_rad_s=0.5)


def test_a_protocol_needing_more_travel_than_the_limits_leave_is_refused() -> None:
    SPEC.require_travel(1.8, protocol="p", source="unit.toml")  # exactly what is left
    with pytest.raises(ProfileError, match=r"\[protocols.p\] needs 0.1 rad more travel"):
        SPEC.require_travel(1.9, protocol="p", source="unit.toml")


def test_move_to_start_ends_held_at_the_start_and_stays_in_the_envelope() -> None:
    move = SPEC.move_to_start(0.7, hold_s=0.1)
    assert move.mode is Mode.POSITION
    assert move.command[-1] == pytest.approx(SPEC.start_rad)
    assert np.all(move.command[-100:] == move.command[-1])
    speed = np.abs(np.diff(move.command)) * SPEC.fs_hz
    assert speed.max() <= SPEC.move_speed_rad_s * 1.001


def test_speed_ramp_rises_smoothly_and_mirrors() -> None:
    up = speed_ramp(0.6, ramp_s=0.1, fs_hz=1000.0, up=True)
    down = speed_ramp(0.6, ramp_s=0.1, fs_hz=1000.0, up=False)
    assert up[-1] == pytest.approx(0.6)
    assert down[-1] == pytest.approx(0.0)
    assert np.all(np.diff(up) > 0)


def test_polled_rows_are_put_back_on_the_command_grid() -> None:
    fs = 100.0
    command = np.linspace(0.0, 1.0, 300)
    excitation = Excitation(name="ramp", mode=Mode.VELOCITY, command=command, fs_hz=fs)
    rng = np.random.default_rng(1)
    kept = np.sort(rng.choice(np.arange(1, 299), size=250, replace=False))
    t = np.concatenate([[0.0], kept / fs, [299 / fs]]) + 0.0003 * rng.standard_normal(252)
    t[0], t[-1] = 0.0, 299 / fs
    recording = Recording(
        columns={
            "time_s": t,
            "position_rad": 2.0 * t,
            "velocity_rad_s": 0 * t,
            "torque_nm": 3.0 * t,
        }
    )
    position, torque, rows = on_command_grid(recording, excitation)
    grid = np.arange(300) / fs
    assert rows == 252
    np.testing.assert_allclose(position, 2.0 * grid, atol=1e-9)
    np.testing.assert_allclose(torque, 3.0 * grid, atol=1e-9)
    short = Recording(columns={k: v[:200] for k, v in recording.columns.items()}, source="short")
    with pytest.raises(IdentificationError, match="short: recording ends"):
        on_command_grid(short, excitation)
