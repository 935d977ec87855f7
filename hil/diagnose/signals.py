"""From a Recording to phase-free motion signals on a uniform grid, with the data's problems.

The regressors of every model in :mod:`hil.diagnose` come from here, through the signal
layer identification uses too (:mod:`hil.identify.kinematics`: the cubic-spline
resampling, the zero-phase Butterworth low-pass and the Savitzky–Golay derivatives).
Velocity and acceleration are derivatives of the *measured position* after the low-pass,
so they carry no phase lag; the drive's own velocity column is never used as a regressor
(it is only compared with the zero-phase derivative to detect a lagging velocity filter,
see :mod:`hil.diagnose.data_issues`).

Irregular timestamps and gaps are handled by resampling onto a uniform grid at the median
sample period; samples inside a gap, next to a gap, next to the ends of a segment (filter
transients) and at saturated effort are marked invalid and never enter a fit.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from hil.errors import IdentificationError
from hil.identify.kinematics import savgol_derivatives, uniform_position, zero_phase_lowpass
from hil.identify.quantisation import quantisation_step
from hil.recording import GAP_FACTOR, AxisKind, Recording, saturated_mask

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Default derivative bandwidth as a fraction of the sample rate.
CUTOFF_FRACTION = 0.125
#: ... and at most this (Hz): the library's effects lie below 0.6 of it (a resonance up
#: to 150 Hz, a current-loop lag's corner, the ripple's and cogging's frequencies). A
#: faster recording of the same axis holds the same physics, while the encoder's
#: quantisation in the inertia column grows as the band's fifth power: at 4 kHz an
#: eighth of the rate let 32 times that noise in, and over another simulator's 4 kHz
#: recordings both hidden effects of a pair came out in 12 of 35 (21 of 35 with the cap;
#: docs/diagnose.md, "Recordings no single simulator shapes").
MAX_CUTOFF_HZ = 250.0
#: Relative spread of sample periods above which sampling counts as irregular.
IRREGULAR_TOLERANCE = 0.01
MIN_VALID_SAMPLES = 200
#: The derivative after the low-pass: Savitzky–Golay over 5 samples, quartic (the five-point
#: central differences; gain error (ωh)⁴/30 for the first, (ωh)⁴/90 for the second).
DERIVATIVE_WINDOW = 5
DERIVATIVE_ORDER = 4


@dataclass(frozen=True, slots=True, kw_only=True)
class Signals:
    """Motion and effort of one recording on a uniform grid (units of the axis kind).

    Attributes
    ----------
    source : str
        The recording's source.
    axis_kind : {"rotary", "linear"}
    fs_hz : float
        Sample rate of the grid: the inverse of the median sample period.
    cutoff_hz : float
        Bandwidth of the zero-phase low-pass behind every derivative and regressor.
    time_s : ndarray
        Uniform sample times, s.
    position : ndarray
        Measured position (interpolated when resampled), rad or m.
    velocity, acceleration : ndarray
        Zero-phase derivatives of position (rad/s, rad/s² or m/s, m/s²).
    effort : ndarray
        Measured torque (N·m) or force (N).
    effort_filtered : ndarray
        ``effort`` through the same zero-phase low-pass as position; fits compare it with
        regressors filtered alike ("parallel filtering"), so the filter's passband droop
        does not bias inertia.
    velocity_reported : ndarray
        The drive's velocity column on the same grid.
    valid : ndarray of bool
        Samples allowed in fits and metrics.
    segments : tuple of (int, int)
        ``(start, stop)`` index ranges without gaps (filters run per segment).
    resampled : bool
        The timestamps were irregular or had gaps, so every column was interpolated onto
        the grid.
    gap_count : int
        Gaps longer than :data:`hil.recording.GAP_FACTOR` median sample periods.
    saturated_count : int
        Samples of the recording (before resampling) at the effort clip value.
    saturation_level : float
        Largest ``|effort|`` among the saturated grid samples; 0 when there are none.
    position_step : float
        The encoder's step, found on the recorded positions before any resampling (a
        resampled position lies between its levels); 0 when it has none.
    """

    source: str
    axis_kind: AxisKind
    fs_hz: float
    cutoff_hz: float
    time_s: FloatArray
    position: FloatArray
    velocity: FloatArray
    acceleration: FloatArray
    effort: FloatArray
    effort_filtered: FloatArray
    velocity_reported: FloatArray
    valid: BoolArray
    segments: tuple[tuple[int, int], ...]
    resampled: bool
    gap_count: int
    saturated_count: int
    saturation_level: float
    position_step: float = 0.0

    def __len__(self) -> int:
        return len(self.time_s)

    @property
    def independence(self) -> float:
        """Fraction of samples that are independent after the low-pass (2·f_c/f_s)."""
        return min(1.0, 2.0 * self.cutoff_hz / self.fs_hz)

    @property
    def decimation(self) -> int:
        """Row step for fits: band-limited signals need no more than ~2.5 samples per cycle."""
        return max(1, int(self.fs_hz / (2.5 * self.cutoff_hz)))

    def rows(self, mask: BoolArray | None = None) -> NDArray[np.intp]:
        """Valid (and ``mask``) sample indices, decimated by :attr:`decimation`.

        Parameters
        ----------
        mask : ndarray of bool, optional
            Samples to keep besides :attr:`valid`, ``len(self)`` long.

        Returns
        -------
        ndarray of intp
            Indices that are valid, in ``mask`` and multiples of :attr:`decimation`.
        """
        keep = self.valid.copy()
        if mask is not None:
            keep &= mask
        keep[np.arange(len(keep)) % self.decimation != 0] = False
        return np.flatnonzero(keep)

    def lowpass(self, values: FloatArray) -> FloatArray:
        """Zero-phase low-pass of ``values`` at :attr:`cutoff_hz`, segment by segment.

        Parameters
        ----------
        values : ndarray
            A column on this grid.

        Returns
        -------
        ndarray
            See :func:`zero_phase_lowpass`.
        """
        return zero_phase_lowpass(values, fs_hz=self.fs_hz, cutoff_hz=self.cutoff_hz,
                                  segments=self.segments)

    def derivative(self, values: FloatArray) -> FloatArray:
        """Five-point Savitzky–Golay time derivative (zero phase), per segment.

        Parameters
        ----------
        values : ndarray
            A column on this grid.

        Returns
        -------
        ndarray
            ``d(values)/dt`` (per second); see :func:`derivatives`.
        """
        return derivatives(values, step_s=1.0 / self.fs_hz, segments=self.segments)[0]


def derivatives(
    values: FloatArray, *, step_s: float, segments: tuple[tuple[int, int], ...]
) -> tuple[FloatArray, FloatArray]:
    """First and second derivatives of a band-limited column, segment by segment.

    Parameters
    ----------
    values : ndarray
        A column on a uniform grid, already low-passed.
    step_s : float
        The grid's period (s).
    segments : tuple of (int, int)
        ``(start, stop)`` index ranges differentiated separately.

    Returns
    -------
    first, second : ndarray
        :func:`hil.identify.kinematics.savgol_derivatives` over
        :data:`DERIVATIVE_WINDOW` samples of order :data:`DERIVATIVE_ORDER` (the local
        quartic at a segment's first and last two samples); 0 outside every segment and
        on segments shorter than the window.
    """
    first = np.zeros_like(values)
    second = np.zeros_like(values)
    for start, stop in segments:
        if stop - start >= DERIVATIVE_WINDOW:
            first[start:stop], second[start:stop] = savgol_derivatives(
                values[start:stop], step_s=step_s, window=DERIVATIVE_WINDOW,
                order=DERIVATIVE_ORDER)
    return first, second


def prepare(recording: Recording, *, cutoff_hz: float | None = None) -> Signals:
    """Resample (if needed), differentiate without phase lag and mark unusable samples.

    Parameters
    ----------
    recording : Recording
        The measured log.
    cutoff_hz : float, optional
        Derivative bandwidth in Hz; default ``fs/8`` (fs: median sample rate), at most
        :data:`MAX_CUTOFF_HZ`.

    Returns
    -------
    Signals
        On the recording's own timestamps, or on a uniform grid at the median sample
        period when they are irregular or have gaps. Invalid: samples in a gap, within
        two samples of a saturated one, and within ``max(3, ⌈2·fs/cutoff_hz⌉)`` samples
        of a segment's ends.

    Raises
    ------
    IdentificationError
        When ``cutoff_hz`` is not in ``(0, fs/2)``, or fewer than 200 usable samples
        remain.
    """
    time_raw = np.asarray(recording.time_s, dtype=np.float64)
    steps = np.diff(time_raw)
    period_s = float(np.median(steps))
    fs_hz = 1.0 / period_s
    gap_index = np.flatnonzero(steps > GAP_FACTOR * period_s)
    irregular = float(np.std(steps) / period_s) > IRREGULAR_TOLERANCE
    resampled = bool(irregular or gap_index.size)
    if cutoff_hz is None:
        cutoff_hz = min(CUTOFF_FRACTION * fs_hz, MAX_CUTOFF_HZ)
    if not 0.0 < cutoff_hz < 0.5 * fs_hz:
        raise IdentificationError(
            f"derivative cutoff {cutoff_hz:g} Hz must lie in (0, {0.5 * fs_hz:g}) Hz"
        )
    sat_raw = _saturation_mask(np.asarray(recording.effort, dtype=np.float64))

    if resampled:
        # position by the identification's spline rule (linear interpolation across a
        # missed poll cuts the path's corner and biases J low); the other columns linearly
        time_s, position = uniform_position(recording.position, time_s=time_raw,
                                            step_s=period_s)
        count = len(time_s)

        def on_grid(values: FloatArray) -> FloatArray:
            return np.asarray(np.interp(time_s, time_raw, values), dtype=np.float64)

        in_gap = np.zeros(count, dtype=bool)
        for index in gap_index:
            in_gap |= (time_s > time_raw[index]) & (time_s < time_raw[index + 1])
        # a grid sample is saturated when its nearest raw sample is
        nearest = np.clip(np.searchsorted(time_raw, time_s), 0, len(time_raw) - 1)
        saturated = sat_raw[nearest]
    else:
        time_s = time_raw

        def on_grid(values: FloatArray) -> FloatArray:
            return np.asarray(values, dtype=np.float64)

        in_gap = np.zeros(len(time_s), dtype=bool)
        saturated = sat_raw
        position = on_grid(recording.position)

    effort = on_grid(recording.effort)
    velocity_reported = on_grid(recording.velocity)
    segments = _segments(in_gap)
    smooth = zero_phase_lowpass(position, fs_hz=fs_hz, cutoff_hz=cutoff_hz, segments=segments)
    velocity, acceleration = derivatives(smooth, step_s=period_s, segments=segments)

    margin = max(3, math.ceil(2.0 * fs_hz / cutoff_hz))
    valid = ~in_gap & ~dilate(saturated, 2)
    for start, stop in segments:
        valid[start : min(stop, start + margin)] = False
        valid[max(start, stop - margin) : stop] = False
    if int(valid.sum()) < MIN_VALID_SAMPLES:
        raise IdentificationError(
            f"{recording.source}: only {int(valid.sum())} usable samples "
            f"(at least {MIN_VALID_SAMPLES} are needed after excluding gaps and saturation)"
        )
    level = float(np.max(np.abs(effort[saturated]))) if saturated.any() else 0.0
    return Signals(
        source=recording.source,
        axis_kind=recording.axis_kind,
        fs_hz=fs_hz,
        cutoff_hz=float(cutoff_hz),
        time_s=time_s,
        position=position,
        velocity=velocity,
        acceleration=acceleration,
        effort=effort,
        effort_filtered=zero_phase_lowpass(
            effort, fs_hz=fs_hz, cutoff_hz=cutoff_hz, segments=segments
        ),
        velocity_reported=velocity_reported,
        valid=valid,
        segments=segments,
        resampled=resampled,
        gap_count=int(gap_index.size),
        saturated_count=int(sat_raw.sum()),
        saturation_level=level,
        position_step=quantisation_step(np.asarray(recording.position)),
    )


def _segments(in_gap: BoolArray) -> tuple[tuple[int, int], ...]:
    """Maximal runs of samples outside gaps."""
    edges = np.diff(np.concatenate(([1], in_gap.astype(np.int8), [1])))
    starts = np.flatnonzero(edges == -1)
    stops = np.flatnonzero(edges == 1)
    return tuple((int(a), int(b)) for a, b in zip(starts, stops, strict=True))


def dilate(mask: BoolArray, width: int) -> BoolArray:
    """``mask`` widened by ``width`` samples on each side."""
    if not mask.any():
        return mask
    kernel = np.ones(2 * width + 1)
    return np.convolve(mask.astype(np.float64), kernel, mode="same") > 0


def _saturation_mask(effort: FloatArray) -> BoolArray:
    """Samples at the effort clip value.

    Two signatures: a value held exactly (a drive reporting its clipped reference, see
    :func:`hil.recording.saturated_mask`), and a plateau at the extreme: at least five
    consecutive samples within three noise standard deviations of the maximum magnitude
    that scatter like noise around a constant (a smooth peak follows a parabola),
    in at least two separate events (a clip value is hit repeatedly).
    """
    mask = saturated_mask(effort)
    noise = _noise_std(effort)
    if noise <= 0.0:
        return mask
    plateaus: list[tuple[int, int]] = []
    for sign in (1.0, -1.0):
        values = sign * effort
        level = float(np.max(values))
        if level <= 0.0:
            continue
        near = values >= level - 3.0 * noise
        long = sorted((r for r in runs(near) if r[1] - r[0] >= 5), key=lambda r: r[0] - r[1])
        plateaus.extend(
            (start, stop) for start, stop in long[:20] if _is_plateau(values[start:stop], noise)
        )
    if len(plateaus) >= 2:  # a clip value is hit repeatedly; one flat peak is not a clip
        for start, stop in plateaus:
            mask[start:stop] = True
    return mask


def _is_plateau(values: FloatArray, noise: float) -> bool:
    """Noise around a constant, not a smooth peak (a parabola explains < half the spread)."""
    if float(np.std(values)) >= 2.0 * noise:
        return False
    index = np.arange(len(values), dtype=np.float64)
    fitted = np.polyval(np.polyfit(index, values, 2), index)
    spread = float(np.sum((values - values.mean()) ** 2))
    return spread == 0.0 or float(np.sum((values - fitted) ** 2)) > 0.5 * spread


def runs(mask: BoolArray) -> list[tuple[int, int]]:
    """``(start, stop)`` of every run of True in ``mask``."""
    edges = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(),
                    strict=True))


def _noise_std(values: FloatArray) -> float:
    """Robust white-noise level from the third difference (MAD)."""
    if len(values) < 10:
        return 0.0
    third = np.diff(values, 3) / math.sqrt(20.0)
    return float(stats.median_abs_deviation(third, scale="normal"))
