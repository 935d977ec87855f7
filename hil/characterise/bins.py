"""Coverage in bins of what each unit itself shows (issue 30): one population-wide method
line can be right on average and wrong for a kind of unit. Per result, the units are split
into thirds by each covariate, a covariate being another result the unit measured on the
same axis (its cogging, friction, cable, loop, …: what a calibration knows of the unit), and
each third is summarised as the whole population is. A third *misses* when its coverage or
RMS interval lies wholly outside the goal at a family-wise 95 % level over every third
looked at (Šidák), so that a population whose ±U is right shows no miss by chance.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

from hil.characterise.run import Row
from hil.characterise.summary import Summary, by_result, summarise_group, verdict

THIRDS = ("low", "middle", "high")
MIN_PRESENT = 0.9  # a covariate must be measured on this share of the result's units
FAMILY_ALPHA = 0.05


@dataclass(frozen=True, slots=True, kw_only=True)
class BinSummary:
    """One third of a result's units, split by one covariate."""

    covariate: str
    third: str  # low, middle, high
    lower: float  # the covariate's range in this third
    upper: float
    summary: Summary

    @property
    def misses(self) -> bool:
        return verdict(self.summary) == "MISSED"


def binned(rows: Sequence[Row]) -> list[BinSummary]:
    """Every result's units in thirds of every covariate, intervals at the family-wise
    level (module text).

    Parameters
    ----------
    rows : sequence of Row
        A population's results (:func:`hil.characterise.run.run_population`).

    Returns
    -------
    list of BinSummary
        In the order of results, covariates and thirds.
    """
    measured: dict[tuple[str, str], dict[str, float]] = {}
    for row in rows:
        measured.setdefault((row.unit, row.axis), {})[row.parameter] = row.value
    splits = []
    for (axis, name), group in by_result(rows).items():
        names = {c for row in group for c in measured[(row.unit, axis)] if c != name}
        for covariate in sorted(names):
            present = [r for r in group if covariate in measured[(r.unit, axis)]]
            if len(present) < max(MIN_PRESENT * len(group), 3 * len(THIRDS)):
                continue
            values = np.array([measured[(r.unit, axis)][covariate] for r in present])
            if np.ptp(values) == 0:
                continue
            order = np.argsort(values, kind="stable")
            splits.append((covariate, [[present[i] for i in part]
                                       for part in np.array_split(order, len(THIRDS))]))
    z = family_z(len(THIRDS) * len(splits))
    found = []
    for covariate, parts in splits:
        for third, part in zip(THIRDS, parts, strict=True):
            span = [measured[(p.unit, p.axis)][covariate] for p in part]
            found.append(BinSummary(covariate=covariate, third=third, lower=min(span),
                                    upper=max(span), summary=summarise_group(part, z)))
    return found


def family_z(cells: int, alpha: float = FAMILY_ALPHA) -> float:
    """The normal quantile that puts ``cells`` two-sided intervals at a family-wise level
    ``1 − alpha`` (Šidák): a population whose ±U is right shows no miss by chance in any of
    them but with probability ``alpha``."""
    return float(stats.norm.isf((1 - (1 - alpha) ** (1 / max(cells, 1))) / 2))


def miss_table(bins: Sequence[BinSummary], *, rows: int = 20) -> list[str]:
    """The thirds that miss (at most ``rows``, the farthest from an RMS of 1 first), as a
    markdown table, and a line counting them."""
    misses = sorted((b for b in bins if b.misses),
                    key=lambda b: -abs(math.log(max(b.summary.rms_normalised, 1e-9))))
    lines = [f"By covariate (each result's units in thirds of each other result the unit "
             f"measured): {len(misses)} of {len(bins)} thirds miss the goal at a family-wise "
             "95 % level" + (f"; the {rows} farthest:" if len(misses) > rows else ".")]
    misses = misses[:rows]
    if misses:
        lines += ["", "| axis | result | third of | range | n | RMS (x−truth)/u [interval] | "
                  "coverage ±U [interval] |", "|---|---|---|---|---|---|---|"]
        for b in misses:
            s = b.summary
            (c_lo, c_hi), (r_lo, r_hi) = s.coverage_interval, s.rms_interval
            lines.append(f"| {s.axis} | {s.parameter} | {b.third} {b.covariate} | "
                         f"{b.lower:.3g} … {b.upper:.3g} | {s.n} | {s.rms_normalised:.2f} "
                         f"[{r_lo:.2f}, {r_hi:.2f}] | {100 * s.coverage:.0f} % "
                         f"[{100 * c_lo:.0f}, {100 * c_hi:.0f}] |")
    return lines
