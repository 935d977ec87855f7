"""Baseline against candidate, result by result: Δ, its uncertainty, p-values, verdicts."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from enum import StrEnum

from hil.compare.budget import SHARING_RULE, DifferenceBudget, difference_budget
from hil.compare.certificates import Certificate, Result
from hil.compare.repeatability import NO_MAP, Repeatability, RepeatabilityMap
from hil.compare.statistics import HOLM_RULE, critical_t, holm, t_p_value
from hil.errors import InputError
from hil.identify.estimate import coverage_factor

INCONCLUSIVE_FRACTION = 0.25  # of the tolerance band (upper − lower limit)

VERDICT_RULE = (
    "Verdicts. A result with a direction ('higher' or 'lower' is better, from its profile "
    "measurement): BETTER or WORSE when the difference is significant (Holm), by its sign; "
    "INCONCLUSIVE when it is not but the interval Δ ± t₁₋α/₂(ν)·u(Δ) reaches a change of a "
    "quarter of the result's tolerance band (|Δ| + t·u(Δ) ≥ (upper − lower limit)/4): the "
    "comparison cannot rule out a change that size; SAME otherwise. A result without a "
    "direction (mechanics): CHANGED when significant, SAME otherwise. MISSING: in the "
    "baseline, not in the candidate; NEW: the other way. Normalised difference "
    "E = Δ / U(Δ), U(Δ) = k·u(Δ) with the certificates' GUM k for ν. Exit 1 when any "
    "result is WORSE, CHANGED or MISSING, else 0; 2 for bad input."
)


class Verdict(StrEnum):
    SAME = "SAME"
    BETTER = "BETTER"
    WORSE = "WORSE"
    INCONCLUSIVE = "INCONCLUSIVE"
    CHANGED = "CHANGED"
    MISSING = "MISSING"
    NEW = "NEW"


FLAGGED = frozenset({Verdict.WORSE, Verdict.CHANGED, Verdict.MISSING})


@dataclass(frozen=True, slots=True, kw_only=True)
class Row:
    """One result of one unit, baseline against candidate (``None``: absent on that side)."""

    serial: str
    parameter: str
    unit: str
    direction: str | None
    baseline: Result | None
    candidate: Result | None
    difference: float | None = None
    difference_pct: float | None = None
    budget: DifferenceBudget | None = None
    normalised: float | None = None
    expanded_uncertainty: float | None = None  # U(Δ) = k·u(Δ)
    p_value: float | None = None
    p_holm: float | None = None
    verdict: Verdict = Verdict.SAME


@dataclass(frozen=True, slots=True, kw_only=True)
class Comparison:
    alpha: float
    rows: tuple[Row, ...]
    warnings: tuple[str, ...]
    notes: tuple[str, ...]
    rules: tuple[str, ...] = (SHARING_RULE, HOLM_RULE, VERDICT_RULE)
    pairs: tuple[tuple[str, str], ...] = field(default=())  # (baseline, candidate) serials

    @property
    def exit_code(self) -> int:
        """1 when anything is WORSE, CHANGED or MISSING, else 0."""
        return 1 if any(r.verdict in FLAGGED for r in self.rows) else 0

    def flagged(self) -> list[Row]:
        return [r for r in self.rows if r.verdict in FLAGGED]


def compare_sides(baseline: Mapping[str, Certificate], candidate: Mapping[str, Certificate],
                  *, alpha: float = 0.05, allow_different_units: bool = False,
                  repeatability: RepeatabilityMap = NO_MAP) -> Comparison:
    """Compare two sides (certificates by serial) result by result.

    Parameters
    ----------
    baseline, candidate : mapping of str to Certificate
        :func:`hil.compare.certificates.load_side` of each side. Directories pair by
        serial; two single certificates pair with each other.
    alpha : float
        Family-wise error rate of the Holm procedure.
    allow_different_units : bool
        Compare different serials, unit types or profiles (else refused).
    repeatability : RepeatabilityMap
        Run-to-run scatter beyond the budgets, by the certificates' axis and result
        (:func:`hil.compare.repeatability.load_repeatability`); none by default.

    Returns
    -------
    Comparison

    Raises
    ------
    InputError
        Unpaired serials, different units or profiles (unless allowed), a result with
        different units of measure on the two sides, ``alpha`` outside (0, 1).
    """
    if not 0 < alpha < 1:
        raise InputError(f"--alpha {alpha} must lie between 0 and 1")
    pairs = _pairs(baseline, candidate, allow_different_units)
    warnings: list[str] = []
    notes: list[str] = []
    rows: list[Row] = []
    for b, c in pairs:
        same_unit = _check_pair(b, c, allow_different_units, warnings, notes)
        protocols = tuple({*b.protocols, *c.protocols})
        for name in [*b.results, *(n for n in c.results if n not in b.results)]:
            rows.append(_row(b.label if same_unit else f"{b.label}→{c.label}", name,
                             b.results.get(name), c.results.get(name), protocols, same_unit,
                             repeatability.entry(b.axis, name)))
    tested = [i for i, r in enumerate(rows) if r.p_value is not None]
    adjusted = holm([rows[i].p_value or 0.0 for i in tested])
    for i, p in zip(tested, adjusted, strict=True):
        rows[i] = _judged(rows[i], p, alpha)
    notes.append(f"repeatability map: {repeatability.source}"
                 + (f" (sha256 {repeatability.sha256[:12]}…)" if repeatability.sha256 else ""))
    return Comparison(alpha=alpha, rows=tuple(rows), warnings=tuple(warnings),
                      notes=tuple(notes), pairs=tuple((b.label, c.label) for b, c in pairs))


def _pairs(baseline: Mapping[str, Certificate], candidate: Mapping[str, Certificate],
           allow: bool) -> list[tuple[Certificate, Certificate]]:
    if len(baseline) == 1 and len(candidate) == 1:
        ((_, b),), ((_, c),) = baseline.items(), candidate.items()
        if b.label != c.label and not allow:
            raise InputError(f"different units: baseline {b.label} ({b.path}), candidate "
                             f"{c.label} ({c.path}); --allow-different-units to compare them")
        return [(b, c)]
    unpaired = sorted(set(baseline) ^ set(candidate))
    if unpaired:
        where = ", ".join(f"{s} only in the {'baseline' if s in baseline else 'candidate'}"
                          for s in unpaired)
        raise InputError(f"serials do not pair: {where}")
    return [(baseline[s], candidate[s]) for s in sorted(baseline)]


def _check_pair(b: Certificate, c: Certificate, allow: bool, warnings: list[str],
                notes: list[str]) -> bool:
    """Refuse different units or profiles unless allowed; warn about the station and
    software. Returns whether the two runs are of the same unit."""
    problems = []
    if b.unit_type != c.unit_type:
        problems.append(f"unit type {b.unit_type!r} vs {c.unit_type!r}")
    b_hash, c_hash, what = b.profile_sha256, c.profile_sha256, "profile SHA-256"
    if b.profile_sha256_without_firmware and c.profile_sha256_without_firmware:
        b_hash, c_hash = b.profile_sha256_without_firmware, c.profile_sha256_without_firmware
        what = "profile SHA-256 without its firmware settings"
    if b_hash != c_hash:
        problems.append(f"{what} {b_hash[:12]}… vs {c_hash[:12]}…")
    if problems and not allow:
        raise InputError(f"{b.label}: different profiles ({'; '.join(problems)}) in {b.path} "
                         f"and {c.path}; --allow-different-units to compare them")
    if problems:
        warnings.append(f"{b.label}: compared although {'; '.join(problems)}")
    if b.station != c.station:
        changed = ", ".join(f"{k} {b.station.get(k)!r} → {c.station.get(k)!r}"
                            for k in sorted({*b.station, *c.station})
                            if b.station.get(k) != c.station.get(k))
        warnings.append(f"{b.label}: station differs ({changed})")
    if (b.software_version, b.git_revision) != (c.software_version, c.git_revision):
        warnings.append(f"{b.label}: software differs (gimbal-hil {b.software_version} "
                        f"{b.git_revision or '?'} → {c.software_version} {c.git_revision or '?'})")
    if b.method_bias_sha256 != c.method_bias_sha256:
        warnings.append(f"{b.label}: method-bias maps differ: their lines do not pair "
                        "and count as independent")
    if b.firmware_version != c.firmware_version:
        notes.append(f"{b.label}: drive firmware {b.firmware_version} → {c.firmware_version}")
    if c.outcome != "PASS" or b.outcome != "PASS":
        notes.append(f"{b.label}: certificate outcome {b.outcome} → {c.outcome}")
    return b.serial == c.serial


def _row(serial: str, name: str, b: Result | None, c: Result | None,
         protocols: tuple[str, ...], same_unit: bool, repeatability: Repeatability | None
         ) -> Row:
    some = b or c
    assert some is not None
    direction = (b.direction if b is not None else None) or (c.direction if c else None)
    if b is None or c is None:
        return Row(serial=serial, parameter=name, unit=some.unit, direction=direction,
                   baseline=b, candidate=c, verdict=Verdict.NEW if b is None else Verdict.MISSING)
    if b.unit != c.unit:
        raise InputError(f"{serial}: result {name} is in {b.unit!r} in the baseline "
                         f"and {c.unit!r} in the candidate")
    budget = difference_budget(b, c, protocols=protocols, same_unit=same_unit,
                               repeatability=repeatability)
    delta, u = c.value - b.value, budget.standard_uncertainty
    expanded = coverage_factor(budget.dof) * u
    return Row(
        serial=serial, parameter=name, unit=b.unit, direction=direction, baseline=b,
        candidate=c, difference=delta,
        difference_pct=100 * delta / abs(b.value) if b.value else None,
        budget=budget, expanded_uncertainty=expanded,
        normalised=delta / expanded if expanded > 0 else (0.0 if delta == 0 else math.inf),
        p_value=t_p_value(delta, u, budget.dof),
    )


def _judged(row: Row, p_holm: float, alpha: float) -> Row:
    assert row.difference is not None
    assert row.budget is not None
    assert row.baseline is not None
    significant = p_holm <= alpha
    if row.direction is None:
        verdict = Verdict.CHANGED if significant else Verdict.SAME
    elif significant:
        better = row.difference > 0 if row.direction == "higher" else row.difference < 0
        verdict = Verdict.BETTER if better else Verdict.WORSE
    else:
        band = row.baseline.upper_limit - row.baseline.lower_limit
        reach = abs(row.difference) + critical_t(alpha, row.budget.dof) * (
            row.budget.standard_uncertainty)
        verdict = (Verdict.INCONCLUSIVE if reach >= INCONCLUSIVE_FRACTION * band
                   else Verdict.SAME)
    return replace(row, p_holm=p_holm, verdict=verdict)
