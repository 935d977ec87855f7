"""Periodic multisines: design (lines on a period's grid, low-crest phases), synthesis, and
per-period analysis (Fourier coefficients of each period, delete-one-period jackknife).

Shared by the velocity loop's FRF (:mod:`hil.closed_loop.frf`) and the resonance FRF
(:mod:`hil.identify.resonance`). A multisine of period ``T₀`` holds whole cycles of every
line, so each period's Fourier coefficients are exact (no leakage) and the periods are
repeated measurements: their scatter is the data's noise.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


def schroeder_phases(count: int) -> FloatArray:
    """Schroeder's phases ``−π·k(k−1)/K`` for ``K`` equal lines: a low crest factor."""
    k = np.arange(1, count + 1)
    return np.asarray(-math.pi * k * (k - 1) / count, dtype=np.float64)


def schroeder_phases_for(amplitudes: Sequence[float]) -> FloatArray:
    """Schroeder's phases for lines of unequal amplitude: ``φₖ = −2π·Σ_{l<k} (k − l)·p_l``
    with ``p_l = a_l² / Σa²`` the lines' power shares (equal amplitudes give
    :func:`schroeder_phases`).

    Parameters
    ----------
    amplitudes : sequence of float
        The lines' amplitudes, in the order of increasing frequency.

    Returns
    -------
    ndarray
        One phase (rad) per line.
    """
    a = np.asarray(amplitudes, dtype=np.float64)
    share = a**2 / float(np.sum(a**2))
    k = np.arange(a.size)
    phases = [-2 * math.pi * float(np.sum((i - k[:i]) * share[:i])) for i in range(a.size)]
    return np.asarray(phases, dtype=np.float64)


def crest_factor(signal: FloatArray) -> float:
    """Peak over RMS of a zero-mean signal (√2 for one sine)."""
    x = np.asarray(signal, dtype=np.float64)
    return float(np.max(np.abs(x)) / np.sqrt(np.mean(x**2)))


def log_harmonics(low_hz: float, high_hz: float, count: int, *, period_s: float) -> tuple[int, ...]:
    """About ``count`` log-spaced lines over ``[low_hz, high_hz]`` on the grid ``k/period_s``.

    Parameters
    ----------
    low_hz, high_hz : float
        The band (Hz); its ends are rounded inwards onto the grid.
    count : int
        Lines asked for; where the log spacing is finer than the grid the duplicates go, so
        fewer may come back.
    period_s : float
        The period (s): the grid's spacing is ``1/period_s``.

    Returns
    -------
    tuple of int
        Increasing line numbers (cycles per period), at least 1.

    Raises
    ------
    ValueError
        A band with no grid line inside it, or fewer than 2 lines asked for.
    """
    first, last = math.ceil(low_hz * period_s - 1e-9), math.floor(high_hz * period_s + 1e-9)
    first = max(first, 1)
    if last <= first or count < 2:
        raise ValueError(f"no {count} lines of {1 / period_s:g} Hz spacing in "
                         f"{low_hz:g}–{high_hz:g} Hz")
    lines = np.unique(np.round(np.geomspace(first, last, count)).astype(int))
    return tuple(int(h) for h in lines)


def multisine(
    *, harmonics: Sequence[int], amplitudes_rad_s: Sequence[float], period_s: float,
    periods: int, fs_hz: float, phases: Sequence[float] | FloatArray | None = None,
) -> FloatArray:
    """``Σ aₖ·cos(2π·hₖ·t/T₀ + φₖ)`` over ``periods`` periods (zero mean), sampled at ``fs_hz``;
    ``phases`` φₖ, by default Schroeder's for equal lines (:func:`schroeder_phases`).

    Raises
    ------
    ValueError
        A period that is not a whole number of samples, or lines, amplitudes and phases that
        differ in number.
    """
    samples = period_s * fs_hz
    if abs(samples - round(samples)) > 1e-9 or round(samples) < 4:
        raise ValueError(f"period {period_s} s is not a whole number of samples at {fs_hz} Hz")
    if len(harmonics) != len(amplitudes_rad_s):
        raise ValueError("one amplitude per harmonic")
    if phases is not None and len(phases) != len(harmonics):
        raise ValueError("one phase per harmonic")
    t = np.arange(round(samples) * periods) / fs_hz
    chosen = schroeder_phases(len(harmonics)) if phases is None else np.asarray(phases)
    out = np.zeros_like(t)
    for h, a, phi in zip(harmonics, amplitudes_rad_s, chosen, strict=True):
        out += a * np.cos(2 * math.pi * h * t / period_s + phi)
    return out


def period_phasors(signal: FloatArray, *, period_samples: int, periods: int,
                   harmonics: Sequence[int]) -> ComplexArray:
    """Fourier coefficients ``X[p, k]`` of each period at each harmonic, fitted jointly with
    a constant and a straight line (a slow drift would leak into the low lines; the line is
    not orthogonal to them, so it is fitted with them, not taken out first).

    Parameters
    ----------
    signal : ndarray
        ``periods·period_samples`` samples, the analysed periods back to back.
    period_samples : int
    periods : int
    harmonics : sequence of int
        Line numbers (cycles per period).

    Returns
    -------
    ndarray, shape (periods, len(harmonics)), complex
        ``X`` with ``x = Re(X·e^{iωt}) = |X|·cos(ωt + ∠X)``.
    """
    n = period_samples
    blocks = np.asarray(signal[: n * periods], dtype=np.float64).reshape(periods, n)
    phase = 2 * math.pi * np.outer(np.arange(n) / n, np.asarray(harmonics, dtype=np.float64))
    ramp = (np.arange(n) - (n - 1) / 2) / n
    design = np.column_stack([np.ones(n), ramp, np.cos(phase), np.sin(phase)])
    coef = np.linalg.lstsq(design, blocks.T, rcond=None)[0]  # (2 + 2K, periods)
    k = len(harmonics)
    cosine, sine = coef[2: 2 + k].T, coef[2 + k:].T
    return np.asarray(cosine - 1j * sine, dtype=np.complex128)


def jackknife(values: FloatArray, full: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Delete-one jackknife: bias-corrected values and standard errors of each column.

    Parameters
    ----------
    values : ndarray, shape (P, m)
        The figures with each of the ``P`` groups left out in turn.
    full : ndarray, shape (m,)
        The figures from every group.

    Returns
    -------
    estimate, standard_error : ndarray, shape (m,)
        ``full`` (not bias-corrected: the correction's noise is larger than the bias) and
        ``√((P−1)/P·Σ(θ₋ᵢ − θ̄)²)``.
    """
    p = values.shape[0]
    mean = values.mean(axis=0)
    se = np.sqrt((p - 1) / p * np.sum((values - mean) ** 2, axis=0))
    return full, se
