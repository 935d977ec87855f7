"""Standard uncertainties and 95 % intervals of the named causes' parameters.

The residual of a fitted model is not white (the effort and every regressor are low-passed
alike, and no model of a real axis is complete), so ``σ²(ΦᵀΦ)⁻¹`` understates the spread
of the coefficients, and so does a noise-only sandwich: what the model still misses
projects onto a cause's columns differently in each experiment of the recording. The
reported covariance is a delete-a-group jackknife over :data:`JACKKNIFE_GROUPS`
contiguous groups of the rows (:func:`jackknife_fit`), its 95 % interval ``value ± k·u``
with ``k`` Student's t for 15 degrees of freedom. The Newey–West sandwich
``(ΦᵀΦ)⁻¹ S (ΦᵀΦ)⁻¹`` (``S = Σ_l w_l (Γ_l + Γ_lᵀ)`` over :data:`HAC_LAGS` lags, Bartlett
weights) still scales the profile likelihood below and the selection's lag.

A searched (nonlinear) parameter gets a profile-likelihood interval: the values whose
RSS (on the rows given) exceeds the best by at most ``χ²₁(0.95)·σ²_HAC`` (the HAC-inflated residual
variance). Where that interval reaches the edge of what the data can show (a Stribeck
velocity below the slowest motion recorded), the parameters are *not separable* and the
report says which excitation would separate them.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from hil.diagnose.model import Designer, Fit, IndexArray, Model, Term, solve
from hil.diagnose.signals import Signals
from hil.identify.estimate import coverage_factor

FloatArray = NDArray[np.float64]

#: Lags of the Newey–West estimate, in fit rows (each row ~ 0.4 cycles of the cutoff).
HAC_LAGS = 25
#: χ²₁ quantile at 95 %: the profile-likelihood threshold of one searched parameter.
CHI2_1_95 = 3.841458820694124
#: Points of the Stribeck-velocity profile.
PROFILE_POINTS = 40


def hac_covariance(matrix: FloatArray, residual: FloatArray, lags: int = HAC_LAGS) -> FloatArray:
    """Newey–West covariance of least-squares coefficients.

    Parameters
    ----------
    matrix : ndarray, shape (n, p)
        The design (Jacobian) on the fitted rows.
    residual : ndarray, shape (n,)
        Target minus fit on those rows.
    lags : int
        Bartlett-weighted lags.

    Returns
    -------
    ndarray, shape (p, p)
        ``(ΦᵀΦ)⁻¹ S (ΦᵀΦ)⁻¹``; infinite everywhere when ``ΦᵀΦ`` is singular.
    """
    n, p = matrix.shape
    scale = np.sqrt(np.sum(matrix**2, axis=0))
    scale[scale == 0.0] = 1.0
    scaled = matrix / scale
    try:
        inverse = np.linalg.inv(scaled.T @ scaled)
    except np.linalg.LinAlgError:
        return np.full((p, p), np.inf)
    scores = scaled * residual[:, None]
    meat = scores.T @ scores
    for lag in range(1, min(lags, n - 1) + 1):
        gamma = scores[lag:].T @ scores[:-lag]
        meat += (1.0 - lag / (lags + 1.0)) * (gamma + gamma.T)
    covariance = inverse @ meat @ inverse * n / max(n - p, 1)
    return np.asarray(covariance / np.outer(scale, scale), dtype=np.float64)


def robust_fit(designer: Designer, fit: Fit, signals: Signals, rows: IndexArray) -> Fit:
    """``fit`` with its covariance replaced by :func:`hac_covariance` on ``rows``.

    Parameters
    ----------
    designer : Designer
    fit : Fit
        Fitted on ``rows`` of ``signals``.
    signals : Signals
    rows : ndarray of intp

    Returns
    -------
    Fit
        Same coefficients; the covariance stays infinite when the fit's is.
    """
    if not np.all(np.isfinite(fit.covariance)):
        return fit
    matrix = designer.design(fit.model, signals, rows)
    residual = signals.effort_filtered[rows] - matrix @ fit.coefficients
    return replace(fit, covariance=hac_covariance(matrix, residual))


#: Contiguous groups of rows of the delete-a-group jackknife (its degrees of freedom: 15).
JACKKNIFE_GROUPS = 16
#: The 95 % coverage factor of a jackknife standard uncertainty (Student t, 15 dof).
JACKKNIFE_COVERAGE = coverage_factor(JACKKNIFE_GROUPS - 1)
#: ... and the 99 % one.
JACKKNIFE_COVERAGE_99 = float(stats.t.ppf(0.995, JACKKNIFE_GROUPS - 1))


def jackknife_fit(designer: Designer, fit: Fit, signals: Signals, rows: IndexArray,
                  groups: int = JACKKNIFE_GROUPS) -> Fit:
    """``fit``'s model fitted on ``rows``, its covariance from a delete-a-group jackknife.

    The rows are cut into ``groups`` contiguous runs; the model is fitted again without
    each, and the coefficients' covariance is ``(G − 1)/G · Σ (β₋g − β̄)(β₋g − β̄)ᵀ``.
    Unlike Newey–West it also covers what the model still misses where that differs
    along the recording (a misfit that projects onto a cause's columns differently in
    each experiment), which the noise-based covariance does not.

    Parameters
    ----------
    designer : Designer
    fit : Fit
        Gives the model (its searched parameters stay fixed).
    signals : Signals
    rows : ndarray of intp
        The rows to fit, in time order.
    groups : int
        Number of contiguous groups.

    Returns
    -------
    Fit
        Fitted on ``rows``; the covariance stays infinite when that fit's is.
    """
    return jackknife_solve(designer.fit(fit.model, signals, rows),
                           designer.design(fit.model, signals, rows),
                           signals.effort_filtered[rows], groups)


def jackknife_solve(full: Fit, matrix: FloatArray, target: FloatArray,
                    groups: int = JACKKNIFE_GROUPS) -> Fit:
    """``full`` with the delete-a-group jackknife covariance of :func:`jackknife_fit`.

    Parameters
    ----------
    full : Fit
        Least squares of ``target`` on ``matrix`` (every row).
    matrix, target : ndarray
        The design and the effort on the rows, in time order.
    groups : int
        Number of contiguous groups.

    Returns
    -------
    Fit
        ``full`` with the jackknife covariance (unchanged when ``full``'s is infinite).
    """
    if not np.all(np.isfinite(full.covariance)):
        return full
    parts = np.array_split(np.arange(len(target)), groups)
    estimates = np.array([
        solve(full.model, matrix[keep], target[keep], n_effective=full.n_effective).coefficients
        for keep in (np.concatenate(parts[:g] + parts[g + 1 :]) for g in range(groups))
    ])
    centred = estimates - estimates.mean(axis=0)
    return replace(full, covariance=(groups - 1) / groups * (centred.T @ centred))


def coverage(fit: Fit) -> float:
    """The 95 % coverage factor for ``fit``'s residual degrees of freedom.

    Parameters
    ----------
    fit : Fit

    Returns
    -------
    float
        :func:`hil.identify.estimate.coverage_factor` of ``n_effective − coefficients``.
    """
    return coverage_factor(max(fit.n_effective - len(fit.coefficients), 1.0))


def _stribeck_velocity_grid(signals: Signals, rows: IndexArray) -> FloatArray:
    speed = np.abs(signals.velocity[rows])
    top = float(np.percentile(speed, 99))
    moving = speed[speed > 1e-3 * top]
    low = max(float(np.percentile(moving, 1)), 1e-3 * top) if moving.size else 1e-3 * top
    return np.geomspace(low, 0.5 * top, PROFILE_POINTS)


def stribeck_profile(designer: Designer, fit: Fit, signals: Signals,
                     rows: IndexArray) -> dict[str, Any] | None:
    """Profile-likelihood intervals of ``T_s`` and ``v_s`` and whether they separate.

    Parameters
    ----------
    designer : Designer
    fit : Fit
        A model with a ``stribeck`` term, fitted on ``rows``.
    signals : Signals
    rows : ndarray of intp

    Returns
    -------
    dict of str to Any or None
        ``stribeck_velocity_rad_s`` and ``static_torque_nm``: ``[low, high]`` 95 %
        intervals; ``separable``: False when the velocity interval reaches the slowest
        motion the data hold (then ``T_s`` and ``v_s`` trade off against each other and
        the intervals are wide); ``excitation``: what would separate them. ``None`` when
        ``fit`` has no Stribeck term.
    """
    from hil.diagnose.effects import stribeck_term

    term = fit.model.term("stribeck")
    if term is None:
        return None
    grid = _stribeck_velocity_grid(signals, rows)
    best_rss = fit.rss
    matrix = designer.design(fit.model, signals, rows)
    residual = signals.effort_filtered[rows] - matrix @ fit.coefficients
    variance = _hac_variance(residual)
    k = coverage(fit)
    inside_v: list[float] = []
    static_low, static_high = math.inf, -math.inf
    for velocity in np.append(grid, term.nonlinear["stribeck_velocity"]):
        model = _replace_term(fit.model, term, stribeck_term(float(velocity)))
        trial = robust_fit(designer, designer.fit(model, signals, rows), signals, rows)
        if trial.rss - best_rss > CHI2_1_95 * variance:
            continue
        inside_v.append(float(velocity))
        static = trial.coef("coulomb") + trial.coef("stribeck_delta")
        weights = np.zeros(len(trial.coefficients))
        weights[trial.model.labels.index("coulomb")] = 1.0
        weights[trial.model.labels.index("stribeck_delta")] = 1.0
        u = math.sqrt(max(float(weights @ trial.covariance @ weights), 0.0))
        static_low, static_high = min(static_low, static - k * u), max(static_high, static + k * u)
    if not inside_v:
        return None
    v_low, v_high = min(inside_v), max(inside_v)
    separable = v_low > grid[0] and v_high < grid[-1]
    result: dict[str, Any] = {
        "stribeck_velocity_rad_s": [v_low, v_high],
        "static_torque_nm": [static_low, static_high],
        "separable": separable,
    }
    if not separable:
        result["excitation"] = (
            f"T_s and v_s are not separated by this recording: v_s lies anywhere in "
            f"[{v_low:.3g}, {v_high:.3g}] (the slowest motion recorded is {grid[0]:.3g}); add "
            f"constant-velocity steps in both directions at about {0.3 * v_high:.3g}, "
            f"{0.6 * v_high:.3g} and {v_high:.3g} (velocity units of the axis), a few "
            "below v_s, so that friction is seen on both sides of the Stribeck dip")
    return result


def _hac_variance(residual: FloatArray) -> float:
    """Long-run variance of ``residual`` per row (Bartlett, :data:`HAC_LAGS` lags)."""
    n = residual.size
    centred = residual - residual.mean()
    total = float(centred @ centred) / n
    for lag in range(1, min(HAC_LAGS, n - 1) + 1):
        total += 2.0 * (1.0 - lag / (HAC_LAGS + 1.0)) * float(centred[lag:] @ centred[:-lag]) / n
    return max(total, float(centred @ centred) / n)


def _replace_term(model: Model, old: Term, new: Term) -> Model:
    return replace(model, terms=tuple(new if term is old else term for term in model.terms))
