"""Declared measurements judged against their limits: PASS / MARGINAL / FAIL.

A tolerance miss is an outcome, not an exception.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

from hil.gum import format_result
from hil.identify.estimate import Estimate, combine_linear
from hil.profile import MeasurementSpec

DECISION_RULE = (
    "Simple acceptance with the expanded uncertainty U (k≈2, ~95 %) stated (ILAC-G8:09/2019 "
    "4.2.1). PASS: value inside the limits, value ± U inside the limits and the value outside "
    "the marginal band next to either limit (a fraction of the distance from the nominal to "
    "that limit). MARGINAL: value inside the limits but within the "
    "marginal band or with a limit inside value ± U. FAIL: value outside the limits. The unit "
    "conforms when every result is PASS or MARGINAL and every protocol ran to completion."
)


class Outcome(StrEnum):
    PASS = "PASS"
    MARGINAL = "MARGINAL"
    FAIL = "FAIL"
    ERROR = "ERROR"  # the protocol did not complete: no conformity statement possible


@dataclass(frozen=True, slots=True, kw_only=True)
class Measurement:
    protocol: str
    spec: MeasurementSpec
    estimate: Estimate
    outcome: Outcome

    @property
    def conforms(self) -> bool:
        """PASS or MARGINAL: inside the limits."""
        return self.outcome in (Outcome.PASS, Outcome.MARGINAL)

    def verdict(self) -> str:
        """``name = value ± U unit → OUTCOME (limits [lo, hi])``, for logs and test reports."""
        e, spec = self.estimate, self.spec
        return (
            f"{spec.name} = {format_result(e.value, e.expanded_uncertainty, spec.unit)} → "
            f"{self.outcome.value} (limits [{spec.lower_limit:.6g}, {spec.upper_limit:.6g}])"
        )

    def as_dict(self) -> dict[str, object]:
        e = self.estimate
        return {
            "parameter": self.spec.name,
            "protocol": self.protocol,
            "value": e.value,
            "unit": self.spec.unit or e.unit,
            "standard_uncertainty": e.standard_uncertainty,
            "coverage_factor": e.coverage_factor,
            "expanded_uncertainty": e.expanded_uncertainty,
            "degrees_of_freedom": e.dof if math.isfinite(e.dof) else None,
            "cramer_rao_std": e.cramer_rao_std,
            "nominal": self.spec.nominal,
            "lower_limit": self.spec.lower_limit,
            "upper_limit": self.spec.upper_limit,
            "outcome": self.outcome.value,
        }


def judge(estimate: Estimate, spec: MeasurementSpec) -> Outcome:
    """Apply :data:`DECISION_RULE`."""
    value, expanded = estimate.value, estimate.expanded_uncertainty
    if not math.isfinite(value) or not spec.lower_limit <= value <= spec.upper_limit:
        return Outcome.FAIL
    # the marginal band is a fraction of the distance from the nominal to each limit, so a
    # one-sided quantity (nominal at its lower limit, smaller is better) has none below
    low_band = spec.marginal_fraction * max(spec.nominal - spec.lower_limit, 0.0)
    high_band = spec.marginal_fraction * max(spec.upper_limit - spec.nominal, 0.0)
    near_limit = value < spec.lower_limit + low_band or value > spec.upper_limit - high_band
    straddles = value - expanded < spec.lower_limit or value + expanded > spec.upper_limit
    return Outcome.MARGINAL if near_limit or straddles else Outcome.PASS


def with_method_accuracy(estimate: Estimate, spec: MeasurementSpec) -> Estimate:
    """Add the method's validated accuracy (profile ``accuracy_pct``) as a Type B component,
    rectangular: ``u_B = a·|value|/√3``; Welch–Satterthwaite dof."""
    if spec.accuracy_rel is None:
        return estimate
    u_b = spec.accuracy_rel * abs(estimate.value) / math.sqrt(3)
    _, u_c, dof = combine_linear(
        [1.0, 1.0], [estimate.value, 0.0], [estimate.standard_uncertainty, u_b],
        [estimate.dof, math.inf],
    )
    return Estimate(
        name=estimate.name,
        value=estimate.value,
        standard_uncertainty=u_c,
        unit=estimate.unit,
        dof=dof,
        cramer_rao_std=estimate.cramer_rao_std,
    )
