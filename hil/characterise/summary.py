"""How the stated uncertainties describe the errors over a population: bias, RMS of the
normalised error, coverage of ±U with their 95 % intervals, and the repeatability of the
same unit under two noise seeds.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hil.characterise.run import PROTOCOLS, Row
from hil.compare.budget import Sharing, classify
from hil.compare.certificates import BudgetLine

FloatArray = NDArray[np.float64]
GOAL_COVERAGE = (0.93, 0.98)
GOAL_RMS = (0.7, 1.3)


@dataclass(frozen=True, slots=True, kw_only=True)
class Summary:
    """Per result: how the stated uncertainty describes the errors over the population."""

    axis: str
    parameter: str
    n: int
    relative: bool  # bias and median_u as fractions of the truth (else in the result's unit)
    bias: float  # mean (x − truth)
    rms_normalised: float
    coverage: float
    median_u: float
    coverage_interval: tuple[float, float]  # Wilson 95 % for the coverage over n units
    rms_interval: tuple[float, float]  # 95 %, from the mean of z² and its standard error


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % interval of a proportion (Wilson score): what ``n`` units can tell of it."""
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(centre - half, 0.0), min(centre + half, 1.0)


def rms_interval(normalised: FloatArray, z: float = 1.96) -> tuple[float, float]:
    """95 % interval of the RMS of ``normalised`` (normal approximation for the mean of
    its squares, with their own scatter: heavy tails widen it)."""
    squares = normalised**2
    mean = float(np.mean(squares))
    error = float(np.std(squares, ddof=1)) / math.sqrt(len(squares)) if len(squares) > 1 else 0
    return math.sqrt(max(mean - z * error, 0.0)), math.sqrt(mean + z * error)


def errors_of(group: Sequence[Row]) -> tuple[bool, FloatArray, FloatArray]:
    """Errors ``x − truth`` and stated ``u``, relative to the truth when every truth is
    positive, else absolute: ``(relative, errors, u)``."""
    truth = np.array([r.truth for r in group])
    relative = bool(np.all(truth > 0))
    scale = truth if relative else np.ones_like(truth)
    errors = (np.array([r.value for r in group]) - truth) / scale
    return relative, errors, np.array([r.standard_uncertainty for r in group]) / scale


def by_result(rows: Iterable[Row]) -> dict[tuple[str, str], list[Row]]:
    """Rows grouped by (axis, result)."""
    groups: dict[tuple[str, str], list[Row]] = {}
    for row in rows:
        groups.setdefault((row.axis, row.parameter), []).append(row)
    return dict(sorted(groups.items()))


def summarise(rows: Iterable[Row]) -> list[Summary]:
    """Bias, RMS normalised error and coverage per axis and result."""
    return [summarise_group(group) for group in by_result(rows).values()]


def by_variant(rows: Iterable[Row]) -> dict[str, list[Summary]]:
    """:func:`summarise` per drawn simulator variant (none when the units have one)."""
    groups: dict[str, list[Row]] = {}
    for row in rows:
        groups.setdefault(row.variant, []).append(row)
    return {} if len(groups) < 2 else {v: summarise(g) for v, g in sorted(groups.items())}


def variant_table(per_variant: Mapping[str, Sequence[Summary]]) -> list[str]:
    """Per variant, how many results meet the goal, and the ones that miss it."""
    lines = []
    for variant, summaries in per_variant.items():
        verdicts = [verdict(s) for s in summaries]
        missed = [s for s, v in zip(summaries, verdicts, strict=True) if v == "MISSED"]
        lines.append(f"{variant}: {verdicts.count('met')} met, {verdicts.count('consistent')} "
                     f"consistent, {len(missed)} missed" + "".join(
                         f"; {s.axis} {s.parameter} {100 * s.coverage:.0f} % / RMS "
                         f"{s.rms_normalised:.2f} (n {s.n})" for s in missed))
    return lines


def summarise_group(group: Sequence[Row], z: float = 1.96) -> Summary:
    """The summary of one result's rows (one axis), its intervals at ``z``."""
    relative, errors, u = errors_of(group)
    covered = sum(r.covered for r in group)
    return Summary(
        axis=group[0].axis, parameter=group[0].parameter, n=len(group), relative=relative,
        bias=float(np.mean(errors)),
        rms_normalised=float(np.sqrt(np.mean((errors / u) ** 2))),
        coverage=covered / len(group),
        median_u=float(np.median(u)),
        coverage_interval=wilson_interval(covered, len(group), z),
        rms_interval=rms_interval(errors / u, z),
    )


def repeatability(first: Mapping[str, Mapping[str, Any]],
                  second: Mapping[str, Mapping[str, Any]]) -> dict[str, float]:
    """``(x₁ − x₂)/√(u₁² + u₂²)`` per result of the same unit under two noise seeds, each
    ``u`` the part of its budget that differs between two runs of one unit
    (:func:`seed_part`)."""
    return {
        name: (float(a["value"]) - float(second[name]["value"]))
        / math.hypot(seed_part(a), seed_part(second[name]))
        for name, a in first.items()
        if name in second and seed_part(a) > 0
    }


def seed_part(result: Mapping[str, Any]) -> float:
    """The part of a result's ``u`` that a second run of the same unit draws anew: its Type A
    lines and the earlier protocols' results measured again (``gimbal-hil compare``'s
    rule); the method's scatter over units, a model's misfit to the unit and resolutions
    repeat, so a rerun cannot check them."""
    lines = result.get("budget") or []
    if not lines:
        return float(result["standard_uncertainty"])
    kept = [line for line in lines if classify(BudgetLine(
        source=line["component"], kind=line["type"],
        standard_uncertainty=float(line["standard_uncertainty"]),
        sensitivity=float(line["sensitivity"]), dof=math.inf,
    ), protocols=PROTOCOLS)[0] is Sharing.INDEPENDENT]
    return math.sqrt(sum(float(line["contribution"]) ** 2 for line in kept))


def verdict(s: Summary) -> str:
    """``met``: coverage and RMS inside the goal; ``consistent``: not both, but the 95 %
    interval of each overlaps its goal (the population cannot tell it from a result that
    meets it); ``MISSED``: an interval lies wholly outside."""
    inside = (GOAL_COVERAGE[0] <= s.coverage <= GOAL_COVERAGE[1]
              and GOAL_RMS[0] <= s.rms_normalised <= GOAL_RMS[1])
    if inside:
        return "met"
    overlaps = (s.coverage_interval[0] <= GOAL_COVERAGE[1]
                and s.coverage_interval[1] >= GOAL_COVERAGE[0]
                and s.rms_interval[0] <= GOAL_RMS[1] and s.rms_interval[1] >= GOAL_RMS[0])
    return "consistent" if overlaps else "MISSED"


def table(summaries: Sequence[Summary]) -> list[str]:
    """The summaries as a markdown table, and a line counting the verdicts."""
    lines = ["| axis | result | n | bias | RMS (x−truth)/u [95 %] | coverage ±U [95 %] | "
             "median u | goal |", "|---|---|---|---|---|---|---|---|"]
    for s in summaries:
        bias, u = ((f"{100 * s.bias:+.2f} %", f"{100 * s.median_u:.2g} %") if s.relative
                   else (f"{s.bias:+.2g}", f"{s.median_u:.2g}"))
        (c_lo, c_hi), (r_lo, r_hi) = s.coverage_interval, s.rms_interval
        lines.append(f"| {s.axis} | {s.parameter} | {s.n} | {bias} | {s.rms_normalised:.2f} "
                     f"[{r_lo:.2f}, {r_hi:.2f}] | {100 * s.coverage:.1f} % [{100 * c_lo:.0f}, "
                     f"{100 * c_hi:.0f}] | {u} | {verdict(s)} |")
    counts = {v: sum(verdict(s) == v for s in summaries) for v in ("met", "consistent",
                                                                   "MISSED")}
    lines.append(f"\n{counts['met']} met, {counts['consistent']} consistent with the goal, "
                 f"{counts['MISSED']} missed, of {len(summaries)}.")
    return lines
