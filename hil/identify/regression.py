"""Least-squares covariance when the residuals are not white."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def newey_west_lags(samples: int) -> int:
    """The usual bandwidth ``⌊4·(n/100)^(2/9)⌋`` (Newey & West 1994), at least 1."""
    bandwidth: float = 4 * (samples / 100) ** (2 / 9)
    return max(1, math.floor(bandwidth))


def newey_west_covariance(design: FloatArray, residual: FloatArray, *, lags: int) -> FloatArray:
    """Covariance of ordinary least-squares coefficients with autocorrelated residuals.

    Newey & West (1987): the sandwich ``(XᵀX)⁻¹ Ω (XᵀX)⁻¹`` with ``Ω`` the Bartlett-weighted
    sum of the residual-weighted regressor products up to ``lags`` apart, scaled by
    ``n/(n − p)``. Residuals with structure the regressors cannot follow (a ripple aliased
    into position bins) are negatively correlated at short lags and count for less than
    white scatter of the same size would.

    Parameters
    ----------
    design : ndarray, shape (n, p)
        The regressors, rows in the order along which residuals are correlated.
    residual : ndarray, shape (n,)
        ``y − X·β̂``.
    lags : int
        Largest lag weighted (see :func:`newey_west_lags`).

    Returns
    -------
    ndarray, shape (p, p)
    """
    n, p = design.shape
    scores = design * residual[:, None]
    meat = scores.T @ scores
    for lag in range(1, lags + 1):
        cross = scores[lag:].T @ scores[:-lag]
        meat += (1 - lag / (lags + 1)) * (cross + cross.T)
    bread = np.linalg.inv(design.T @ design)
    return np.asarray(bread @ meat @ bread * n / (n - p), dtype=np.float64)
