"""The uncertainty of a difference: only what the two runs do not share.

Two calibrations of the same unit on the same station share their systematic inputs: the
same error counted on both sides cancels in ``Δ = candidate − baseline``, and counting it
twice would hide real regressions. :data:`SHARING_RULE` states, per budget line, which is
which; :func:`difference_budget` applies it.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum

from hil.compare.certificates import BudgetLine, Result
from hil.compare.repeatability import Repeatability
from hil.identify.estimate import combine_linear

SHARING_RULE = (
    "Budget of the difference Δ = candidate − baseline. Independent (each run's own "
    "contribution counts, root sum of squares): Type A lines (this run's noise) and Type B "
    "lines that are an earlier protocol's result measured again in each run (the source "
    "ends with that protocol's name in parentheses, e.g. 'current-loop time constant τ "
    "taken out (current_loop)'). Shared by two runs of the same unit on the same station "
    "(fully correlated, enters as the difference of its two contributions, zero when "
    "equal): every other Type B line: the method's error over the simulated population "
    "('method: …'), the allowance for physics the simulator lacks ('allowance …'), a "
    "resolution (a sample grid's or an LSB's rounding, '… resolution …'), a "
    "station's calibration constant. A line found on one side only, and every line when "
    "the serials differ (--allow-different-units), counts as independent. Where identical-"
    "firmware reruns scatter more than the budgets state (fixtures/compare_repeatability."
    "toml, measured by benchmarks/bench_compare.py), that excess is one more independent "
    "line per run. Degrees of freedom: Welch–Satterthwaite over the lines that remain."
)

# a re-measured input names the protocol that measured it: "… (gravity_cable: m·g·e, φ)"
_PROTOCOL_REFERENCE = re.compile(r"\(([a-z][a-z0-9_]*)(?::[^()]*)?\)\s*$")


class Sharing(StrEnum):
    INDEPENDENT = "independent"
    SHARED = "shared"


def classify(line: BudgetLine, *, protocols: Sequence[str], same_unit: bool = True
             ) -> tuple[Sharing, str]:
    """Shared or independent between two runs, and why (:data:`SHARING_RULE`).

    Parameters
    ----------
    line : BudgetLine
        A budget line of one certificate result.
    protocols : sequence of str
        The protocols the certificate names (what a re-measured input may reference).
    same_unit : bool
        Both runs are of the same unit (else nothing is shared).

    Returns
    -------
    sharing : Sharing
    reason : str
        A short reason for the output.
    """
    if not same_unit:
        return Sharing.INDEPENDENT, "different units"
    if line.kind == "A":
        return Sharing.INDEPENDENT, "Type A noise"
    reference = _PROTOCOL_REFERENCE.search(line.source)
    if reference is not None and reference.group(1) in protocols:
        return Sharing.INDEPENDENT, f"re-measured by {reference.group(1)}"
    if line.source.startswith("method:"):
        return Sharing.SHARED, "method error, same unit"
    if line.source.startswith("allowance"):
        return Sharing.SHARED, "allowance"
    if "resolution" in line.source:
        return Sharing.SHARED, "resolution, the same grid on both runs"
    return Sharing.SHARED, "systematic Type B"


@dataclass(frozen=True, slots=True, kw_only=True)
class DifferenceLine:
    """One line of the difference's budget: ``contribution`` in the result's unit."""

    source: str
    sharing: Sharing
    reason: str
    baseline_contribution: float  # cᵢ·uᵢ (0 when the line is absent on that side)
    candidate_contribution: float
    contribution: float  # what Δ keeps: RSS of both (independent) or their difference
    baseline_dof: float = math.inf
    candidate_dof: float = math.inf


@dataclass(frozen=True, slots=True, kw_only=True)
class DifferenceBudget:
    standard_uncertainty: float
    dof: float
    lines: tuple[DifferenceLine, ...]


def difference_budget(baseline: Result, candidate: Result, *, protocols: Sequence[str],
                      same_unit: bool = True, repeatability: Repeatability | None = None
                      ) -> DifferenceBudget:
    """``u(Δ)`` and its Welch–Satterthwaite degrees of freedom.

    Parameters
    ----------
    baseline, candidate : Result
        The same result from each run; lines are paired by their source text.
    protocols : sequence of str
        Protocols named on either certificate.
    same_unit : bool
        Both runs are of the same unit.
    repeatability : Repeatability or None
        Measured run-to-run scatter beyond the budget: one more independent line per run.

    Returns
    -------
    DifferenceBudget
        Independent lines contribute ``√(c_b² + c_c²)`` with ``ν`` their combined
        Welch–Satterthwaite dof; a shared line contributes ``|c_c − c_b|`` (``ν = ∞``).
    """
    lines: list[DifferenceLine] = []
    rest = list(candidate.budget)
    for line in baseline.budget:
        partner = next((c for c in rest if c.source == line.source and c.kind == line.kind),
                       None)
        if partner is not None:
            rest.remove(partner)
        lines.append(_pair(line, partner, protocols=protocols, same_unit=same_unit))
    lines += [_pair(None, c, protocols=protocols, same_unit=same_unit) for c in rest]
    if repeatability is not None and repeatability.scatter > 0:
        b, c = (repeatability.standard_uncertainty(r.value) for r in (baseline, candidate))
        lines.append(DifferenceLine(
            source=repeatability.source, sharing=Sharing.INDEPENDENT, reason="measured",
            baseline_contribution=b, candidate_contribution=c, contribution=math.hypot(b, c),
            baseline_dof=repeatability.pairs, candidate_dof=repeatability.pairs))
    # Welch–Satterthwaite over every input that remains, each side's independent lines apart
    weights: list[float] = []
    dofs: list[float] = []
    for d in lines:
        if d.sharing is Sharing.SHARED:
            weights.append(d.contribution)
            dofs.append(math.inf)
        else:
            weights += [d.baseline_contribution, d.candidate_contribution]
            dofs += [d.baseline_dof, d.candidate_dof]
    _, u, dof = combine_linear(weights, [0.0] * len(weights), [1.0] * len(weights), dofs)
    return DifferenceBudget(standard_uncertainty=u, dof=dof, lines=tuple(lines))


def _pair(baseline: BudgetLine | None, candidate: BudgetLine | None, *,
          protocols: Sequence[str], same_unit: bool) -> DifferenceLine:
    some = baseline or candidate
    assert some is not None
    b = baseline.signed_contribution if baseline is not None else 0.0
    c = candidate.signed_contribution if candidate is not None else 0.0
    if baseline is None or candidate is None:
        sharing = Sharing.INDEPENDENT
        reason = f"{'candidate' if baseline is None else 'baseline'} only"
    else:
        sharing, reason = classify(some, protocols=protocols, same_unit=same_unit)
    if sharing is Sharing.SHARED:
        return DifferenceLine(source=some.source, sharing=sharing, reason=reason,
                              baseline_contribution=b, candidate_contribution=c,
                              contribution=abs(c - b))
    return DifferenceLine(
        source=some.source, sharing=sharing, reason=reason, baseline_contribution=b,
        candidate_contribution=c, contribution=math.hypot(b, c),
        baseline_dof=baseline.dof if baseline is not None else math.inf,
        candidate_dof=candidate.dof if candidate is not None else math.inf)
