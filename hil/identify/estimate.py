"""An identified value with its standard uncertainty (GUM), and linear propagation helpers."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

COVERAGE_PROBABILITY = 0.9545  # the coverage of k = 2 for a normal distribution


def coverage_factor(dof: float) -> float:
    """GUM coverage factor for ~95 % coverage.

    Parameters
    ----------
    dof : float
        Effective degrees of freedom of the standard uncertainty (``inf`` when known).

    Returns
    -------
    float
        2 for 50 or more degrees of freedom; Student-t's two-sided 95.45 % quantile for
        fewer (at least one degree of freedom is assumed).
    """
    if not math.isfinite(dof) or dof >= 50:
        return 2.0
    return float(stats.t.ppf(0.5 + COVERAGE_PROBABILITY / 2, max(dof, 1.0)))


@dataclass(frozen=True, slots=True, kw_only=True)
class Estimate:
    """An identified value with its standard uncertainty (GUM): ``value ± k·u`` in ``unit``.

    Attributes
    ----------
    name : str
        The declared measurement it answers (``inertia_kg_m2``, ...).
    value, standard_uncertainty : float
        The estimate and its combined standard uncertainty ``u``.
    unit : str
    dof : float
        Effective degrees of freedom (Welch–Satterthwaite) behind ``u``; sets ``k``.
    cramer_rao_std : float or None
        The bound on the standard deviation of any unbiased estimator given the same data,
        when known.
    """

    name: str
    value: float
    standard_uncertainty: float
    unit: str
    dof: float = math.inf
    cramer_rao_std: float | None = None

    @property
    def coverage_factor(self) -> float:
        return coverage_factor(self.dof)

    @property
    def expanded_uncertainty(self) -> float:
        return self.coverage_factor * self.standard_uncertainty

    @property
    def relative_uncertainty(self) -> float:
        return self.standard_uncertainty / abs(self.value) if self.value else math.inf


def combine_linear(
    weights: ArrayLike,
    values: ArrayLike,
    uncertainties: ArrayLike,
    dofs: ArrayLike,
) -> tuple[float, float, float]:
    """Combine independent inputs linearly: ``y = Σ wᵢ·xᵢ``.

    Parameters
    ----------
    weights, values, uncertainties, dofs : array_like
        Sensitivities ``wᵢ``, input values ``xᵢ``, their standard uncertainties ``uᵢ`` and
        degrees of freedom ``νᵢ`` (``inf`` for a Type B component).

    Returns
    -------
    value, standard_uncertainty, dof : float
        ``y``, ``u(y) = √Σ(wᵢuᵢ)²`` and the Welch–Satterthwaite effective degrees of
        freedom ``u(y)⁴ / Σ (wᵢuᵢ)⁴/νᵢ`` (``inf`` when every component has infinite dof).
    """
    w = np.asarray(weights, dtype=np.float64)
    x = np.asarray(values, dtype=np.float64)
    u = np.asarray(uncertainties, dtype=np.float64)
    nu = np.asarray(dofs, dtype=np.float64)
    contributions = (w * u) ** 2
    variance = float(contributions.sum())
    denominator = float(np.sum(contributions**2 / nu))
    dof = variance**2 / denominator if denominator > 0 else math.inf
    return float(w @ x), math.sqrt(variance), dof
