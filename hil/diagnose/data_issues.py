"""Problems of the data itself: reported as such, never as physics.

Saturation and gaps are excluded from every fit (see :mod:`hil.diagnose.signals`);
quantisation and a lagging velocity filter are measured and reported, and feed the data
fields of the extended profile (``encoder_counts_per_rev``, ``velocity_filter_hz``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hil.diagnose.signals import Signals, _noise_std
from hil.errors import IdentificationError
from hil.identify.quantisation import quantisation_step
from hil.recording import Recording

FloatArray = NDArray[np.float64]

#: The reported velocity lags when it trails the zero-phase derivative by more than this
#: many samples (a backward difference alone trails by half a sample).
VELOCITY_LAG_SAMPLES = 1.0
MAX_LAG_SAMPLES = 60


@dataclass(frozen=True, slots=True, kw_only=True)
class DataIssue:
    """One problem of the data, as the report lists it.

    Attributes
    ----------
    kind : str
        ``saturation``, ``gaps``, ``irregular_sampling``, ``quantisation``,
        ``velocity_filter_lag`` or ``effort_noise``.
    severity : str
        ``"warning"`` (affects the data used) or ``"info"``.
    message : str
        One line for a reader.
    values : dict of str to Any
        The numbers behind the message (see :func:`find_issues`).
    """

    kind: str  # saturation, gaps, irregular_sampling, quantisation, velocity_filter_lag, ...
    severity: str  # "warning" (affects the data used) or "info"
    message: str
    values: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """``kind``, ``severity``, ``message`` and the :attr:`values` in one flat dict."""
        return {"kind": self.kind, "severity": self.severity, "message": self.message,
                **self.values}


#: Below this sample rate a recording cannot hold a servo axis's dynamics (loops at
#: 0.5-10 kHz, the diagnosis's band an eighth of the rate): most likely its time column is
#: not in seconds.
MIN_SAMPLE_RATE_HZ = 50.0


def refuse_unusable(signals: Signals) -> None:
    """Data no diagnosis can use, refused in one line before any fit.

    Raises
    ------
    IdentificationError
        The samples are too far apart for the axis's dynamics (a time column in
        milliseconds reads as 1 Hz), or the axis never moves.
    """
    if signals.fs_hz < MIN_SAMPLE_RATE_HZ:
        raise IdentificationError(
            f"{signals.source}: time_s steps by {1 / signals.fs_hz:.3g} s "
            f"({signals.fs_hz:.3g} Hz, under {MIN_SAMPLE_RATE_HZ:g} Hz): too slow for a "
            "servo axis; is the time column in milliseconds? (time_s is seconds)")
    if not np.ptp(signals.position[signals.valid]) > 0:
        raise IdentificationError(f"{signals.source}: the axis never moves (the position is "
                                  "constant): nothing to identify")
    ratio = _position_to_velocity_scale(signals)
    for name, scale in UNIT_SLIPS.items():
        if abs(ratio / scale - 1.0) < UNIT_SLIP_TOLERANCE:
            raise IdentificationError(
                f"{signals.source}: the position's derivative is {ratio:.4g} × the recorded "
                f"velocity: position_rad looks like {name} (the format's position is rad or m)")


#: a position column in another unit than the velocity's: the factor its derivative shows
UNIT_SLIPS = {"degrees": 180.0 / math.pi, "milliradians (or mm)": 1000.0}
#: how close to a slip's factor the measured one must come (a velocity filter's droop
#: and noise change the RMS ratio by a few percent, never by a factor)
UNIT_SLIP_TOLERANCE = 0.05


def _position_to_velocity_scale(signals: Signals) -> float:
    """RMS of the position's derivative over RMS of the recorded velocity (1 when both are
    in the same unit; nan without a usable velocity column)."""
    reported = signals.velocity_reported[signals.valid]
    derived = signals.velocity[signals.valid]
    reported_rms = float(np.sqrt(np.mean(reported**2))) if reported.size else 0.0
    if not (math.isfinite(reported_rms) and reported_rms > 0):
        return math.nan
    return float(np.sqrt(np.mean(derived**2))) / reported_rms


def velocity_delay_samples(signals: Signals) -> float:
    """Delay of the reported velocity behind the zero-phase derivative (samples).

    Parameters
    ----------
    signals : Signals
        Gives ``velocity_reported``, the zero-phase ``velocity`` and the valid samples.

    Returns
    -------
    float
        The lag within ±60 samples that maximises their correlation over every fourth
        valid sample, refined by a parabola through the peak; positive when the reported
        velocity trails. 0 when fewer than 100 samples are usable or the reported
        velocity is constant on them.
    """
    reported = signals.velocity_reported
    reference = signals.velocity
    valid = signals.valid
    lags = np.arange(-MAX_LAG_SAMPLES, MAX_LAG_SAMPLES + 1)
    n = len(reference)
    core = np.flatnonzero(valid)
    core = core[(core >= MAX_LAG_SAMPLES) & (core < n - MAX_LAG_SAMPLES)][::4]
    if core.size < 100 or float(np.std(reported[core])) == 0.0:
        return 0.0
    scores = np.array([float(np.dot(reported[core], reference[core - lag])) for lag in lags])
    best = int(np.argmax(scores))
    if 0 < best < len(lags) - 1:
        left, centre, right = scores[best - 1 : best + 2]
        curvature = left - 2 * centre + right
        shift = 0.5 * (left - right) / curvature if curvature != 0 else 0.0
        return float(lags[best] + shift)
    return float(lags[best])


def encoder_counts(issues: Iterable[DataIssue]) -> int | None:
    """The encoder's counts per revolution the quantisation issue found (``None``: not found,
    or not a whole number of counts per revolution)."""
    counts = next((i.values.get("counts_per_rev") for i in issues if i.kind == "quantisation"),
                  None)
    return counts if isinstance(counts, int) else None


def find_issues(recording: Recording, signals: Signals) -> list[DataIssue]:
    """Every data problem of ``recording`` (as prepared into ``signals``).

    Parameters
    ----------
    recording : Recording
        The log as read (timestamps, position and effort before resampling).
    signals : Signals
        ``recording`` prepared (see :func:`hil.diagnose.signals.prepare`).

    Returns
    -------
    list of DataIssue
        In this order, when present: ``saturation`` (values ``samples``, ``level``),
        ``gaps`` (``count``), ``irregular_sampling`` (``period_spread``,
        ``resampled_hz``), ``quantisation`` (``step``, ``counts_per_rev`` (None on a
        linear axis), ``acceleration_noise``), ``velocity_filter_lag`` (``delay_samples``,
        ``equivalent_cutoff_hz``, for a delay above one sample); always last
        ``effort_noise`` (``std``, effort units).
    """
    issues: list[DataIssue] = []
    if signals.saturated_count:
        issues.append(DataIssue(
            kind="saturation", severity="warning",
            message=(f"{signals.saturated_count} samples at the effort clip value "
                     f"{signals.saturation_level:.6g}: excluded from every fit"),
            values={"samples": signals.saturated_count, "level": signals.saturation_level},
        ))
    if signals.gap_count:
        issues.append(DataIssue(
            kind="gaps", severity="warning",
            message=(f"{signals.gap_count} gap(s) longer than 5 sample periods: samples in "
                     "and next to them are excluded"),
            values={"count": signals.gap_count},
        ))
    steps = np.diff(recording.time_s)
    spread = float(np.std(steps) / np.median(steps))
    if signals.resampled and spread > 0.01:
        issues.append(DataIssue(
            kind="irregular_sampling", severity="info",
            message=(f"timestamps are irregular (period spread {100 * spread:.0f} %): "
                     f"resampled to a uniform {signals.fs_hz:.6g} Hz grid"),
            values={"period_spread": spread, "resampled_hz": signals.fs_hz},
        ))
    step = quantisation_step(np.asarray(recording.position))
    if step > 0:
        rotary = signals.axis_kind == "rotary"
        counts = round(2 * math.pi / step) if rotary else None
        noise = step / math.sqrt(12) * (2 * math.pi * signals.cutoff_hz) ** 2 * math.sqrt(
            2 * signals.cutoff_hz / signals.fs_hz / 5)
        where = f" ({counts} counts/rev)" if counts else ""
        issues.append(DataIssue(
            kind="quantisation", severity="info",
            message=(f"position is quantised in steps of {step:.4g}{where}; after the "
                     f"{signals.cutoff_hz:.4g} Hz low-pass it adds about {noise:.3g} "
                     "(position units)/s² of noise to the acceleration"),
            values={"step": step, "counts_per_rev": counts, "acceleration_noise": noise},
        ))
    delay = velocity_delay_samples(signals)
    if delay > VELOCITY_LAG_SAMPLES:
        # a first-order filter on a backward difference trails by 1/(2π f_c) + T/2
        lag_s = (delay - 0.5) / signals.fs_hz
        cutoff = 1.0 / (2 * math.pi * lag_s) if lag_s > 0 else math.inf
        issues.append(DataIssue(
            kind="velocity_filter_lag", severity="info",
            message=(f"the recorded velocity trails the derivative of position by "
                     f"{delay:.2f} samples ({1e3 * delay / signals.fs_hz:.3g} ms), like a "
                     f"first-order filter at {cutoff:.4g} Hz; it is not used as a regressor"),
            values={"delay_samples": delay, "equivalent_cutoff_hz": cutoff},
        ))
    noise_std = _noise_std(np.asarray(recording.effort))
    issues.append(DataIssue(
        kind="effort_noise", severity="info",
        message=f"white effort noise ≈ {noise_std:.3g} (from the third difference)",
        values={"std": noise_std},
    ))
    return issues
