"""Least-squares fits of harmonics of a known phase, with a polynomial trend: the one
numerics behind the article's orthogonal correlation, the current-loop and resonance
phasors, the J/B/T_c harmonic components and the cogging design."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def harmonic_columns(phase_rad: FloatArray, orders: Sequence[int]) -> FloatArray:
    """Design columns ``cos(k·φ), sin(k·φ)`` for each order ``k``, in that order.

    Parameters
    ----------
    phase_rad : array
        The phase φ of each sample (``ω·t`` for a sine in time, θ for orders of a turn).
    orders : sequence of int
        The harmonics ``k``.

    Returns
    -------
    array, shape (len(phase_rad), 2·len(orders))
    """
    phase = np.asarray(phase_rad, dtype=np.float64)
    columns = [f(k * phase) for k in orders for f in (np.cos, np.sin)]
    return np.column_stack(columns) if columns else np.zeros((phase.size, 0))


def polynomial_columns(x: FloatArray, order: int) -> FloatArray:
    """Design columns ``1, x, …, x^order`` (none for ``order < 0``).

    Parameters
    ----------
    x : array
        The trend variable, best centred and scaled to about [−1, 1].
    order : int
        The highest power.

    Returns
    -------
    array, shape (len(x), order + 1)
    """
    values = np.asarray(x, dtype=np.float64)
    if order < 0:
        return np.zeros((values.size, 0))
    return np.column_stack([values**p for p in range(order + 1)])


@dataclass(frozen=True, slots=True)
class HarmonicFit:
    """Coefficients of ``y ≈ Σ_k (cos_k·cos kφ + sin_k·sin kφ) + Σ_p trend_p·x^p``.

    Attributes
    ----------
    cos, sin : array, shape (len(orders),) + y.shape[1:]
        The in-phase and quadrature amplitudes per order (and per column of ``y``).
    trend : array, shape (trend columns,) + y.shape[1:]
        The trend's coefficients.
    """

    cos: FloatArray
    sin: FloatArray
    trend: FloatArray

    def interleaved(self) -> FloatArray:
        """The amplitudes as one array, order by order.

        Returns
        -------
        ndarray, shape (2·len(orders),) + y.shape[1:]
            ``cos_1, sin_1, cos_2, sin_2, …`` stacked along the first axis.
        """
        return np.stack([self.cos, self.sin], axis=1).reshape(-1, *self.cos.shape[1:])


def fit_harmonics(
    phase_rad: FloatArray,
    values: FloatArray,
    *,
    orders: Sequence[int] = (1,),
    trend: FloatArray | None = None,
) -> HarmonicFit:
    """Least-squares amplitudes of the harmonics ``orders`` of ``phase_rad`` in ``values``.

    For uniform samples over whole periods and a constant trend the amplitudes are the
    article's correlation sums ``(2/N)·Σ y·cos kφ`` and ``(2/N)·Σ y·sin kφ``; the fit stays
    unbiased for irregular timestamps or a subset of samples.

    Parameters
    ----------
    phase_rad : array
        The phase of each sample.
    values : array, shape (N,) or (N, M)
        The signal(s) fitted (each column on its own).
    orders : sequence of int
        The harmonics.
    trend : array, shape (N, P), optional
        Nuisance columns fitted with them (:func:`polynomial_columns`); none by default.

    Returns
    -------
    HarmonicFit
    """
    design = harmonic_columns(phase_rad, orders)
    if trend is not None:
        design = np.column_stack([design, trend])
    coefficients = np.linalg.lstsq(design, np.asarray(values, dtype=np.float64), rcond=None)[0]
    count = 2 * len(orders)
    return HarmonicFit(
        cos=np.asarray(coefficients[0:count:2]),
        sin=np.asarray(coefficients[1:count:2]),
        trend=np.asarray(coefficients[count:]),
    )
