"""The tests behind a comparison: Student-t p-values and Holm's step-down adjustment."""

from __future__ import annotations

import math
from collections.abc import Sequence

from scipy import stats

HOLM_RULE = (
    "Family-wise error: Holm's step-down over the p-values of every result compared "
    "(all units together). With p₍₁₎ ≤ … ≤ p₍ₘ₎, the adjusted p₍ᵢ₎ is "
    "max over j ≤ i of min(1, (m − j + 1)·p₍ⱼ₎); a difference is significant when its "
    "adjusted p ≤ alpha, so the chance of flagging any unchanged result is at most alpha."
)


def t_p_value(difference: float, standard_uncertainty: float, dof: float) -> float:
    """Two-sided p-value of ``difference`` against zero (Student t, ``dof`` degrees).

    Parameters
    ----------
    difference : float
        ``Δ = candidate − baseline``.
    standard_uncertainty : float
        ``u(Δ)``.
    dof : float
        Effective degrees of freedom of ``u(Δ)`` (``inf``: the normal distribution).

    Returns
    -------
    float
        ``2·P(T > |Δ|/u)``; 1 for no difference, 0 for a difference with ``u = 0``.
    """
    if standard_uncertainty <= 0:
        return 1.0 if difference == 0 else 0.0
    t = abs(difference) / standard_uncertainty
    if not math.isfinite(dof):
        return float(2 * stats.norm.sf(t))
    return float(2 * stats.t.sf(t, dof))


def critical_t(alpha: float, dof: float) -> float:
    """Two-sided Student-t quantile ``t₁₋α/₂(ν)`` (normal for ``ν = ∞``)."""
    if not math.isfinite(dof):
        return float(stats.norm.ppf(1 - alpha / 2))
    return float(stats.t.ppf(1 - alpha / 2, dof))


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm-adjusted p-values (:data:`HOLM_RULE`), in the input's order.

    Parameters
    ----------
    p_values : sequence of float
        Raw p-values of the family.

    Returns
    -------
    list of float
        Adjusted p-values: reject the hypotheses whose adjusted p is at most alpha.
    """
    m = len(p_values)
    order = sorted(range(m), key=lambda i: p_values[i])
    adjusted = [0.0] * m
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p_values[i]))
        adjusted[i] = running
    return adjusted
