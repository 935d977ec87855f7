"""Residual analysis: what the simulation gets wrong, MATLAB ``resid``-style.

Tests run on the residual of a model over the valid samples, decimated to the analysis
bandwidth (the residual is low-passed like the regressors, so neighbouring full-rate
samples are correlated by construction). Whiteness: the normalised autocorrelation at
lags 1..25 against the 99 % bound ``±2.576/√N`` and the Ljung–Box statistic
``Q = N(N+2)·Σ ρ_k²/(N−k)`` (χ²(25)). Independence from the input: the normalised
cross-correlation with the input at lags −25..25 against the same bound.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.signal import welch
from scipy.special import chdtrc

from hil.diagnose.signals import Signals

FloatArray = NDArray[np.float64]

LAGS = 25
BOUND_Z = 2.5758293035489004  # 99 %
BINS = 40


def _normalised(values: FloatArray) -> FloatArray:
    centred: FloatArray = values - values.mean()
    norm = float(np.sqrt(centred @ centred))
    return centred / norm if norm > 0 else centred


def residual_tests(residual: FloatArray, inputs: FloatArray, *, input_name: str
                   ) -> dict[str, Any]:
    """Autocorrelation, cross-correlation with ``inputs`` and Ljung–Box on ``residual``.

    Parameters
    ----------
    residual, inputs : ndarray
        Same length, on the analysis rows.
    input_name : str
        Names ``inputs`` in the result.

    Returns
    -------
    dict of str to Any
        ``samples``; ``bound_99``; ``autocorrelation`` (``lags`` 1..25, ``values``,
        ``outside_bound``, ``white``); ``cross_correlation`` (``input``, ``lags``
        −25..25, ``values``, ``outside_bound``, ``independent``); ``ljung_box``
        (``lags``, ``q``, ``p_value``, ``white_at_1pct``).
    """
    n = len(residual)
    e = _normalised(residual)
    u = _normalised(inputs)
    bound = BOUND_Z / math.sqrt(n)
    auto = np.array([float(e[k:] @ e[: n - k]) for k in range(1, LAGS + 1)])
    cross = np.array([
        float(e[k:] @ u[: n - k]) if k >= 0 else float(e[: n + k] @ u[-k:])
        for k in range(-LAGS, LAGS + 1)
    ])
    q = n * (n + 2) * float(np.sum(auto**2 / (n - np.arange(1, LAGS + 1))))
    return {
        "samples": n,
        "bound_99": bound,
        "autocorrelation": {
            "lags": list(range(1, LAGS + 1)),
            "values": auto.tolist(),
            "outside_bound": int(np.sum(np.abs(auto) > bound)),
            "white": bool(np.all(np.abs(auto) <= bound)),
        },
        "cross_correlation": {
            "input": input_name,
            "lags": list(range(-LAGS, LAGS + 1)),
            "values": cross.tolist(),
            "outside_bound": int(np.sum(np.abs(cross) > bound)),
            "independent": bool(np.all(np.abs(cross) <= bound)),
        },
        "ljung_box": {
            "lags": LAGS,
            "q": q,
            "p_value": float(chdtrc(LAGS, q)),
            "white_at_1pct": bool(chdtrc(LAGS, q) > 0.01),
        },
    }


def binned(x: FloatArray, y: FloatArray, bins: int = BINS) -> dict[str, list[float]]:
    """Mean and standard deviation of ``y`` in equal-width bins of ``x``.

    Parameters
    ----------
    x, y : ndarray
    bins : int
        Number of bins over ``[min(x), max(x)]``.

    Returns
    -------
    dict of str to list
        ``centre``, ``mean``, ``std`` (population) and ``count`` of the non-empty bins.
    """
    edges = np.linspace(float(np.min(x)), float(np.max(x)), bins + 1)
    index = np.clip(np.digitize(x, edges) - 1, 0, bins - 1)
    count = np.bincount(index, minlength=bins).astype(np.float64)
    total = np.bincount(index, weights=y, minlength=bins)
    square = np.bincount(index, weights=y * y, minlength=bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / count, np.nan)
        std = np.sqrt(np.maximum(np.where(count > 0, square / count, np.nan) - mean**2, 0.0))
    centres = 0.5 * (edges[:-1] + edges[1:])
    keep = count > 0
    return {"centre": centres[keep].tolist(), "mean": mean[keep].tolist(),
            "std": std[keep].tolist(), "count": count[keep].astype(int).tolist()}


def spectrum(signals: Signals, residual: FloatArray, peaks: int = 5) -> dict[str, Any]:
    """Welch spectrum of the residual (invalid samples zeroed) and its strongest peaks.

    Parameters
    ----------
    signals : Signals
        Gives the sample rate, the valid samples and the band.
    residual : ndarray
        Over every sample of ``signals``.
    peaks : int
        How many local maxima to report.

    Returns
    -------
    dict of str to Any
        ``frequency_hz`` and ``psd`` (effort units²/Hz) up to ``signals.cutoff_hz``;
        ``peaks_hz``: the strongest local maxima, in ascending frequency.
    """
    values = np.where(signals.valid, residual, 0.0)
    nperseg = int(min(len(values), 2 ** int(math.log2(max(signals.fs_hz * 2, 256)))))
    freq, power = welch(values, fs=signals.fs_hz, nperseg=nperseg)
    band = freq <= signals.cutoff_hz
    freq, power = freq[band], power[band]
    local = np.flatnonzero((power[1:-1] > power[:-2]) & (power[1:-1] >= power[2:])) + 1
    top = local[np.argsort(-power[local])][:peaks]
    return {
        "frequency_hz": freq.tolist(),
        "psd": power.tolist(),
        "peaks_hz": [float(freq[i]) for i in sorted(top)],
    }


def analyse(signals: Signals, prediction: FloatArray, *,
            velocity_cmd: FloatArray | None) -> dict[str, Any]:
    """Residual tests, spectrum and residual against position and velocity.

    Parameters
    ----------
    signals : Signals
    prediction : ndarray
        A model's effort on every sample; the residual is ``effort_filtered`` minus it.
    velocity_cmd : ndarray or None
        The velocity command on the same grid: the input the residual is
        cross-correlated with; ``None`` uses ``signals.velocity``.

    Returns
    -------
    dict of str to Any
        ``tests`` (:func:`residual_tests` plus ``decimation``), ``spectrum``
        (:func:`spectrum`), ``against_position`` and ``against_velocity``
        (:func:`binned`). Tests and bins use the valid, decimated rows.
    """
    residual = signals.effort_filtered - prediction
    rows = signals.rows()
    if velocity_cmd is not None:
        inputs, name = velocity_cmd, "velocity command"
    else:
        inputs, name = signals.velocity, "velocity (derivative of position)"
    tests = residual_tests(residual[rows], inputs[rows], input_name=name)
    tests["decimation"] = signals.decimation
    return {
        "tests": tests,
        "spectrum": spectrum(signals, residual),
        "against_position": binned(signals.position[rows], residual[rows]),
        "against_velocity": binned(signals.velocity[rows], residual[rows]),
    }
