"""Newey–West covariance: right for white residuals, and for residuals with a short-period
pattern the regressors cannot follow (what position bins make of cogging), where the
white-residual covariance overstates the coefficients' scatter."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from hil.identify.regression import FloatArray, newey_west_covariance, newey_west_lags

N = 48
X = np.column_stack([np.cos(np.linspace(-1.3, 1.3, N)), np.sin(np.linspace(-1.3, 1.3, N)),
                     np.linspace(-1.3, 1.3, N), np.ones(N)])


def _scatter_and_stated(
    make_residual: Callable[[np.random.Generator], FloatArray], draws: int = 3000
) -> tuple[float, float, float]:
    """True SD of the slope coefficient, mean stated u (Newey–West), mean stated u (white)."""
    rng = np.random.default_rng(5)
    slopes, nw, white = [], [], []
    for _ in range(draws):
        y = X @ np.array([0.015, 0.001, 0.004, 0.0]) + make_residual(rng)
        coef = np.linalg.lstsq(X, y, rcond=None)[0]
        r = y - X @ coef
        slopes.append(coef[2])
        nw.append(np.sqrt(newey_west_covariance(X, r, lags=newey_west_lags(N))[2, 2]))
        white.append(np.sqrt(r @ r / (N - 4) * np.linalg.inv(X.T @ X)[2, 2]))
    return float(np.std(slopes)), float(np.mean(nw)), float(np.mean(white))


def test_white_residuals_give_the_ordinary_covariance() -> None:
    true_sd, nw, white = _scatter_and_stated(lambda rng: 1e-4 * rng.standard_normal(N))
    assert white == pytest.approx(true_sd, rel=0.06)
    assert nw == pytest.approx(true_sd, rel=0.2)


def test_aliased_ripple_is_not_counted_as_white_scatter() -> None:
    k = np.arange(N)

    def ripple(rng: np.random.Generator) -> FloatArray:
        phase = rng.uniform(0, 2 * np.pi)
        return 4e-4 * np.cos(2 * np.pi * k / 3 + phase) + 5e-5 * rng.standard_normal(N)

    true_sd, nw, white = _scatter_and_stated(ripple)
    assert white > 2 * true_sd  # the white formula overstates it
    assert nw == pytest.approx(true_sd, rel=0.35)
