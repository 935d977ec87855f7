"""The current-loop lag's search pieces (hil/diagnose/lag.py) on small synthetic signals."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from hil.diagnose.lag import quantisation_noise, through_level_changes
from hil.diagnose.model import (
    Designer,
    Model,
    base_terms,
    fractional_shift,
    friction_direction,
    moving_rows,
)
from hil.diagnose.signals import prepare
from hil.recording import Recording


def _recording(position: np.ndarray, fs_hz: float = 2000.0) -> Recording:
    time_s = np.arange(position.size) / fs_hz
    return Recording(source="synthetic", columns={
        "time_s": time_s, "position_rad": position, "velocity_rad_s": np.gradient(position),
        "torque_nm": np.sin(2 * np.pi * 3.0 * time_s)})


def test_continuous_position_has_no_quantisation_noise() -> None:
    time_s = np.arange(8000) / 2000.0
    signals = prepare(_recording(0.3 * np.sin(2 * np.pi * 1.7 * time_s) + 1e-4 * time_s**2))
    assert quantisation_noise(signals) == ()


def test_stand_in_error_stays_within_half_a_step() -> None:
    """Each stand-in is a re-quantisation error of the recording's own step: |e| ≤ q/2."""
    step = 2 * math.pi / 2**16
    time_s = np.arange(8000) / 2000.0
    position = np.round(0.3 * np.sin(2 * np.pi * 1.7 * time_s) / step) * step
    noise = quantisation_noise(prepare(_recording(position)))
    assert len(noise) == 4
    for signals in noise:
        assert np.max(np.abs(signals.position)) <= step / 2 * (1 + 1e-9)
        assert np.std(signals.position) > step / 6  # a real error, not zeros


def test_level_changes_trace_a_creeping_axis_within_a_fraction_of_a_step() -> None:
    """Creeping at 0.13 steps per sample: the quantised reading is off by up to q/2, the
    line through its changes of level by the curvature between two changes only."""
    step = 1e-5
    sample = np.arange(6000, dtype=np.float64)
    truth = 0.13 * step * sample + 40 * step * np.sin(2 * np.pi * sample / 6000) + 0.3 * step
    quantised = np.round(truth / step) * step
    inner = slice(100, -100)
    traced = through_level_changes(quantised)
    assert np.max(np.abs(traced - truth)[inner]) < 0.1 * step
    assert np.max(np.abs(quantised - truth)[inner]) > 0.45 * step


def test_stand_ins_carry_the_true_error_s_power_where_the_axis_creeps() -> None:
    """A slow sine (at most 0.05 steps per sample): the stand-ins' acceleration noise has
    the power of the true quantisation error's, through the same filters, within 20 %
    (0.57 × when the low-passed position itself was re-quantised: it still steps)."""
    fs_hz, step = 2000.0, 2 * math.pi / 2**20
    time_s = np.arange(16000) / fs_hz
    truth = 0.05 * step * fs_hz / (2 * np.pi * 0.5) * np.sin(2 * np.pi * 0.5 * time_s) + 0.37 * step
    quantised = np.round(truth / step) * step
    signals = prepare(_recording(quantised, fs_hz))
    exact = prepare(_recording(truth, fs_hz))
    rows = signals.rows()
    true_power = np.mean((signals.acceleration - exact.acceleration)[rows] ** 2)
    stand_in_power = np.mean([np.mean(n.acceleration[rows] ** 2)
                              for n in quantisation_noise(signals)])
    assert 0.8 < stand_in_power / true_power < 1.25


def test_moving_rows_leave_out_sticking_and_its_spread_only() -> None:
    """A stretch standing still is left out with the low-pass's margin; a reversal is not."""
    fs_hz = 2000.0
    time_s = np.arange(12000) / fs_hz
    paused = time_s.copy()  # the axis sticks for 0.2 s, then moves on
    paused[5000:5400] = time_s[5000]
    paused[5400:] -= 400 / fs_hz
    position = 0.3 * np.sin(2 * np.pi * 1.3 * paused)
    signals = prepare(_recording(position, fs_hz))
    rows = signals.rows()
    kept = moving_rows(signals, rows)
    margin = math.ceil(2.0 * signals.fs_hz / signals.cutoff_hz)
    assert not np.any((kept >= 5000) & (kept < 5400))
    assert np.any((kept > 5400 + 3 * margin) & (kept < 5600))
    assert np.any((kept < 5000 - 3 * margin) & (kept > 4800))
    # a reversal of the sine passing through the standstill band in one sample: kept
    reversal = round(3 * fs_hz / (4 * 1.3))
    assert friction_direction(signals)[reversal] == 0
    assert np.any(np.abs(kept - reversal) <= 2)
    assert kept.size < rows.size


def test_moving_rows_keep_every_row_when_most_stand_still() -> None:
    fs_hz = 2000.0
    time_s = np.arange(8000) / fs_hz
    paused = np.minimum(time_s, 1000 / fs_hz) + np.maximum(time_s - 7000 / fs_hz, 0.0)
    position = 0.3 * np.sin(2 * np.pi * 1.3 * paused)
    signals = prepare(_recording(position, fs_hz))
    rows = signals.rows()
    assert np.array_equal(moving_rows(signals, rows), rows)


def test_friction_delay_takes_friction_columns_from_the_earlier_velocity() -> None:
    """Friction columns (Coulomb, viscous) are built from the velocity ``delay`` samples
    earlier; the inertia column is not, and the delayed columns are cached apart."""
    fs_hz = 2000.0
    time_s = np.arange(8000) / fs_hz
    signals = prepare(_recording(0.3 * np.sin(2 * np.pi * 1.3 * time_s), fs_hz))
    inertia, viscous, coulomb = base_terms()
    designer = Designer()
    plain = designer.columns(coulomb, signals)
    delayed = designer.columns(coulomb, signals, 0.5)
    earlier = fractional_shift(signals.velocity[:, None], -0.5, np.arange(len(signals)))[:, 0]
    expected = signals.lowpass(friction_direction(replace(signals, velocity=earlier)))
    assert np.allclose(delayed[:, 0], expected)
    assert not np.allclose(plain, delayed)
    assert np.allclose(designer.columns(viscous, signals, 0.5)[:, 0], earlier)
    assert np.array_equal(designer.columns(inertia, signals, 0.5),
                          designer.columns(inertia, signals))
    model = Model(terms=(inertia, viscous, coulomb), friction_delay=0.5)
    assert model.n_params == Model(terms=(inertia, viscous, coulomb)).n_params + 1
    assert np.allclose(designer.design(model, signals)[:, 2], expected)
