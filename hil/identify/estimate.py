"""An identified value with its standard uncertainty (GUM), its budget, and linear
propagation helpers."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import stdtrit

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
    # stdtrit is what scipy.stats.t.ppf evaluates, without scipy.stats' second of imports
    return float(stdtrit(max(dof, 1.0), 0.5 + COVERAGE_PROBABILITY / 2))


@dataclass(frozen=True, slots=True, kw_only=True)
class Component:
    """One line of an uncertainty budget (GUM 8): an input's standard uncertainty and how
    strongly the result depends on it.

    Attributes
    ----------
    source : str
        What the input is (``"torque noise: scatter of the per-period components"``).
    kind : {"A", "B"}
        Type A (evaluated from this measurement's data) or Type B (other evidence).
    standard_uncertainty : float
        ``u(xᵢ)`` of the input, in ``unit``.
    unit : str
        The input's unit.
    sensitivity : float
        ``cᵢ = ∂y/∂xᵢ`` (result units per input unit).
    dof : float
        Degrees of freedom of ``u(xᵢ)`` (``inf`` for a Type B component).
    """

    source: str
    kind: Literal["A", "B"]
    standard_uncertainty: float
    unit: str
    sensitivity: float = 1.0
    dof: float = math.inf

    @property
    def contribution(self) -> float:
        """``|cᵢ|·u(xᵢ)``: this input's share of the result's standard uncertainty."""
        return abs(self.sensitivity) * self.standard_uncertainty

    @classmethod
    def from_change(cls, *, source: str, standard_uncertainty: float, unit: str,
                    change: float) -> Component:
        """A Type B input whose sensitivity is found numerically (GUM 5.1.3): the result
        re-evaluated with the input at ``x + u(x)`` moved by ``change``."""
        sensitivity = change / standard_uncertainty if standard_uncertainty > 0 else 0.0
        return cls(source=source, kind="B", standard_uncertainty=standard_uncertainty,
                   unit=unit, sensitivity=sensitivity)


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
    budget : tuple of Component
        The named inputs behind ``standard_uncertainty`` (empty: one Type A component,
        the data's scatter as the estimator evaluated it).
    """

    name: str
    value: float
    standard_uncertainty: float
    unit: str
    dof: float = math.inf
    cramer_rao_std: float | None = None
    budget: tuple[Component, ...] = ()

    @property
    def coverage_factor(self) -> float:
        return coverage_factor(self.dof)

    @property
    def expanded_uncertainty(self) -> float:
        return self.coverage_factor * self.standard_uncertainty

    @property
    def relative_uncertainty(self) -> float:
        return self.standard_uncertainty / abs(self.value) if self.value else math.inf

    def components(self) -> tuple[Component, ...]:
        """The budget; an estimate without one is a single Type A component."""
        if self.budget:
            return self.budget
        return (Component(source=TYPE_A_SOURCE, kind="A", unit=self.unit,
                          standard_uncertainty=self.standard_uncertainty, dof=self.dof),)

    def scaled(self, factor: float, *, name: str, unit: str) -> Estimate:
        """``factor · self`` as another result (``name``, ``unit``), every budget line
        kept with its sensitivity scaled."""
        lines = [dataclasses.replace(c, sensitivity=c.sensitivity * factor)
                 for c in self.components()]
        renamed = dataclasses.replace(self, name=name, unit=unit, cramer_rao_std=None)
        return with_budget(renamed, lines, value=self.value * factor)

    def with_components(self, *added: Component, value: float | None = None) -> Estimate:
        """This estimate with more budget lines (and, for a correction, a new value).

        Parameters
        ----------
        *added : Component
            Inputs to add; zero contributions are kept off the budget.
        value : float or None
            The corrected value, when the inputs include a correction.

        Returns
        -------
        Estimate
            ``u`` the root sum of squares of every contribution, Welch–Satterthwaite dof.
        """
        kept = tuple(c for c in added if c.contribution > 0)
        return with_budget(self, (*self.components(), *kept),
                           value=self.value if value is None else value)


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


TYPE_A_SOURCE = "measurement noise: scatter of the data (Type A)"


def with_budget(estimate: Estimate, budget: Sequence[Component], *, value: float) -> Estimate:
    """``estimate`` with ``value`` and the uncertainty the budget's lines combine to.

    Parameters
    ----------
    estimate : Estimate
        Its name, unit and Cramér–Rao bound are kept.
    budget : sequence of Component
        Independent inputs.
    value : float
        The result's value.

    Returns
    -------
    Estimate
        ``u = √Σ(cᵢuᵢ)²``, dof by Welch–Satterthwaite (:func:`combine_linear`).
    """
    lines = tuple(budget)
    _, u, dof = combine_linear(
        [c.sensitivity for c in lines], [0.0] * len(lines),
        [c.standard_uncertainty for c in lines], [c.dof for c in lines],
    )
    return dataclasses.replace(estimate, value=value, standard_uncertainty=u, dof=dof,
                               budget=lines)
