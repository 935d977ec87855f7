"""A weighted least-squares fit whose weights are estimated from each point's own scatter.

Each phase of the current-loop fit is weighted by the scatter of its own few blocks (an
estimate with ``blocks − 1`` degrees of freedom). A point whose scatter came out low by
chance weighs too much, and the fit's ``t = error/u`` is heavier-tailed than the Student-t
of the pooled degrees of freedom: over the demo azimuth's eight phases of 10 blocks each,
with u as fitted ``|t| > 2`` in 10 % of fits, not 5 %, and ``|t| > 4.8`` in 0.07 % (a
normal: 2·10⁻⁶). Widening u by ``√(χ²/ν)`` where that exceeds one takes much of the tail
out of the fits it widens and leaves the others with less of it; each branch has its own.

:func:`draw_fits` simulates that fit under its linearised model (the phases' errors and
their variance estimates drawn, a fixed stream, so one recording always gets one answer);
:func:`coverage_dof` reads from the draws the degrees of freedom whose Student-t gives a
value's ±k·u its 95.45 %, and :func:`chi2_p_value` the probability of a χ² as large.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import brentq
from scipy.special import stdtrit

from hil.identify.estimate import COVERAGE_PROBABILITY, coverage_factor

FloatArray = NDArray[np.float64]

#: draws of the fit (the 95.45 % point's own relative sd is ~1 %, a p-value of 0.01's ~0.0007)
DRAWS = 20_000
#: at and above these degrees of freedom ``coverage_factor`` says 2 (the normal's k)
NORMAL_DOF = 50.0


@dataclass(frozen=True, slots=True)
class DrawnFits:
    """The linearised fit over many draws of its data.

    Attributes
    ----------
    errors : numpy.ndarray
        (draws, parameters): each draw's parameter errors, in the units of ``design``'s
        columns.
    covariances : numpy.ndarray
        (draws, parameters, parameters): each draw's covariance from its own weights.
    chi2 : numpy.ndarray
        (draws,): each draw's weighted sum of squared misfits.
    dof : int
        The fit's own degrees of freedom: points − parameters.
    """

    errors: FloatArray
    covariances: FloatArray
    chi2: FloatArray
    dof: int


def draw_fits(design: FloatArray, scatter_dof: FloatArray, *, draws: int = DRAWS,
              seed: int = 0) -> DrawnFits:
    """The weighted fit of ``design`` (rows: points, in units of their true standard
    deviations) over ``draws`` draws of unit-normal errors, each point weighted by a
    variance estimate with ``scatter_dof`` degrees of freedom (χ²/ν about its true one).

    Parameters
    ----------
    design : numpy.ndarray
        (points, parameters): ∂(weighted residual)/∂parameter at the fit.
    scatter_dof : numpy.ndarray
        (points,): degrees of freedom of each point's variance estimate (blocks − 1).
    draws, seed
        The draws and their stream.

    Returns
    -------
    DrawnFits
    """
    rng = np.random.default_rng(seed)
    points = len(scatter_dof)
    errors = rng.standard_normal((draws, points))
    weights = 1.0 / (rng.chisquare(scatter_dof, size=(draws, points)) / scatter_dof)
    parameters = design.shape[1]
    outer = (design[:, :, None] * design[:, None, :]).reshape(points, -1)
    normal = (weights @ outer).reshape(-1, parameters, parameters)  # Σ wᵢ aᵢaᵢᵀ per draw
    right = (weights * errors) @ design
    covariances = _inverse(normal)
    beta = np.einsum("dkl,dl->dk", covariances, right)
    misfit = errors - beta @ design.T
    return DrawnFits(errors=beta, covariances=covariances,
                     chi2=np.sum(weights * misfit**2, axis=1), dof=points - parameters)


def _inverse(matrices: FloatArray) -> FloatArray:
    """The inverses of a stack of symmetric matrices: by cofactors for 2 × 2 and 3 × 3 (a
    third of the time of :func:`numpy.linalg.inv` over a stack of 20 000)."""
    size = matrices.shape[-1]
    if size == 2:
        a, b, d = matrices[:, 0, 0], matrices[:, 0, 1], matrices[:, 1, 1]
        inverse = np.stack([np.stack([d, -b], axis=-1), np.stack([-b, a], axis=-1)], axis=-2)
        return np.asarray(inverse / (a * d - b * b)[:, None, None], dtype=np.float64)
    if size == 3:
        m = matrices
        cofactors = np.empty_like(m)
        for i in range(3):
            for j in range(3):
                r0, r1 = (i + 1) % 3, (i + 2) % 3
                c0, c1 = (j + 1) % 3, (j + 2) % 3
                cofactors[:, j, i] = m[:, r0, c0] * m[:, r1, c1] - m[:, r0, c1] * m[:, r1, c0]
        determinant = np.einsum("dk,dk->d", m[:, 0, :], cofactors[:, :, 0])
        return np.asarray(cofactors / determinant[:, None, None], dtype=np.float64)
    return np.asarray(np.linalg.inv(matrices), dtype=np.float64)


def chi2_p_value(fits: DrawnFits, observed_chi2: float) -> float:
    """The probability of a χ² at least ``observed_chi2`` (the draws' rank, never 0)."""
    return float((1 + np.count_nonzero(fits.chi2 >= observed_chi2)) / (1 + len(fits.chi2)))


def coverage_dof(fits: DrawnFits, gradient: FloatArray, *, inflated: bool) -> float:
    """The degrees of freedom to state for ``gradient · parameters``: those whose Student-t
    95.45 % point is the draws' ``|error/u|`` 95.45 % point.

    The fit's u is widened by ``√(χ²/ν)`` where that exceeds one; ``inflated`` says which
    branch the observed fit took, and only the draws that took it are read (the coverage
    stated is the coverage given the branch).

    Returns
    -------
    float
        The degrees of freedom (``inf`` where the point is the normal's, 2 or below, or no
        draw took the branch).
    """
    g = np.asarray(gradient, dtype=np.float64)
    variance = np.einsum("k,dkl,l->d", g, fits.covariances, g)
    scale = np.maximum(1.0, fits.chi2 / fits.dof) if fits.dof > 0 else np.ones(len(fits.chi2))
    took = scale > 1.0 if inflated else scale <= 1.0
    if not np.any(took):
        return math.inf
    t = (fits.errors @ g)[took] / np.sqrt(variance[took] * scale[took])
    point = float(np.quantile(np.abs(t), COVERAGE_PROBABILITY))
    if point <= coverage_factor(math.inf):
        return math.inf
    if point <= _student_point(NORMAL_DOF):  # k is 2 from here on
        return NORMAL_DOF
    if point >= _student_point(1.0):
        return 1.0
    return float(brentq(lambda nu: _student_point(nu) - point, 1.0, NORMAL_DOF))


def _student_point(dof: float) -> float:
    return float(stdtrit(dof, 0.5 + COVERAGE_PROBABILITY / 2))
