"""``spc PARAM``: capability, I-MR chart, Nelson rules and EWMA of one parameter's series."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from hil.errors import InputError
from hil.fleet.baseline import Baseline
from hil.fleet.capability import Capability, capability, moving_ranges
from hil.fleet.charts import (
    EwmaChart,
    EwmaSettings,
    ImrLimits,
    ewma_chart,
    imr_limits,
    imr_limits_from,
)
from hil.fleet.fmt import at_u, index_text, typical_u
from hil.fleet.rules import DEFAULT_RULES, DESCRIPTIONS, nelson_rules, parse_rules
from hil.fleet.series import SeriesPoint, ordered, single_unit, spec_limits, values_of


@dataclass(frozen=True, slots=True, kw_only=True)
class SpcResult:
    """Everything ``spc PARAM`` shows; :meth:`table` for a person, :meth:`to_json` for tools."""

    parameter: str
    unit: str
    points: list[SeriesPoint]
    values: NDArray[np.float64]
    excluded_reference: int
    lower_limit: float | None
    upper_limit: float | None
    nominal: float | None
    capability: Capability | None
    capability_note: str
    limits: ImrLimits
    baseline: Baseline | None
    rules: tuple[int, ...]
    rule_hits: dict[int, list[int]]
    mr_hits: list[int]
    ewma: EwmaChart | None
    typical_u: float = field(default=0.0)
    no_spread: str = ""  # the sentence shown instead of charts and rules when σ = 0

    @property
    def n(self) -> int:
        """Number of runs in the series."""
        return len(self.points)

    @property
    def charted(self) -> bool:
        """Whether the series has a spread to chart and judge (σ > 0)."""
        return not self.no_spread

    def table(self) -> str:
        """The readable report (values at the decimal place their typical U allows)."""
        u = self.typical_u
        unit = f" {self.unit}" if self.unit else ""
        first, last = self.points[0].started_at, self.points[-1].started_at
        lines = [f"SPC {self.parameter}{f' ({self.unit})' if self.unit else ''}: "
                 f"n = {self.n} runs, {first:%Y-%m-%d} … {last:%Y-%m-%d}"
                 + (f", {self.excluded_reference} reference runs left out"
                    if self.excluded_reference else "")]
        lines.append(f"Specification   lower {at_u(self.lower_limit, u)}   nominal "
                     f"{at_u(self.nominal, u)}   upper {at_u(self.upper_limit, u)}{unit}")
        if self.no_spread:
            lines.append(self.no_spread[0].upper() + self.no_spread[1:] + ".")
            lines.append("No signal.")
            return "\n".join(lines)
        if self.capability is None:
            lines.append(f"Capability      {self.capability_note}")
        else:
            c = self.capability
            lines.append(f"Capability ({100 * c.confidence:.0f} % confidence intervals, "
                         f"n = {c.n}; within σ {at_u(c.sigma_within, u)}, overall σ "
                         f"{at_u(c.sigma_overall, u)}{unit})")
            for est in (c.cp, c.cpk, c.pp, c.ppk):
                lines.append(f"  {est.name:<4}{index_text(est):<22}{est.method}")
        lim = self.limits
        source = ("frozen baseline of "
                  f"{self.baseline.n} runs, {self.baseline.first_started_at[:10]} … "
                  f"{self.baseline.last_started_at[:10]}" if self.baseline else
                  "this series (trial limits)")
        lines.append(f"I chart         centre {at_u(lim.centre, u)}   LCL {at_u(lim.lcl, u)}   "
                     f"UCL {at_u(lim.ucl, u)}{unit}")
        lines.append(f"                limits from {source}")
        lines.append(f"MR chart        centre {at_u(lim.mr_centre, u)}   UCL "
                     f"{at_u(lim.mr_ucl, u)}{unit}")
        lines.append("Nelson rules " + ", ".join(str(r) for r in self.rules) + ":")
        for rule in self.rules:
            hits = self.rule_hits[rule]
            lines.append(f"  {rule}  {DESCRIPTIONS[rule]:<54}"
                         + (self._where(hits) if hits else "none"))
        lines.append(f"  {'MR beyond its UCL (shown, not gated)':<57}"
                     + (self._where(self.mr_hits) if self.mr_hits else "none"))
        if self.ewma is not None:
            e = self.ewma
            lines.append(f"EWMA (λ = {e.lam:g}, L = {e.width:g}, exact limits)   "
                         + (self._where(e.signals) if e.signals else "no signal"))
        lines.append("SIGNAL: investigate before trusting this series" if has_signal(self)
                     else "No signal.")
        return "\n".join(lines)

    def _where(self, indices: Sequence[int]) -> str:
        shown = [f"#{i + 1} {self.points[i].serial} {self.points[i].started_at:%Y-%m-%d}"
                 for i in indices[:3]]
        more = f" (+{len(indices) - 3} more)" if len(indices) > 3 else ""
        return f"{len(indices)} point(s): " + ", ".join(shown) + more

    def to_json(self) -> dict[str, object]:
        """Full precision; indices are 0-based positions in ``points``."""
        mr = np.concatenate([[np.nan], moving_ranges(self.values)])
        return {
            "parameter": self.parameter, "unit": self.unit, "n": self.n,
            "excluded_reference": self.excluded_reference,
            "specification": {"lower_limit": self.lower_limit, "upper_limit": self.upper_limit,
                              "nominal": self.nominal},
            "capability": self.capability.to_dict() if self.capability else None,
            "capability_note": self.capability_note,
            "no_spread": self.no_spread or None,
            "limits": self.limits.to_dict(),
            "baseline": self.baseline.to_dict() if self.baseline else None,
            "rules": {str(r): {"description": DESCRIPTIONS[r], "indices": self.rule_hits[r],
                               "run_ids": [self.points[i].run_id for i in self.rule_hits[r]]}
                      for r in self.rules},
            "mr_beyond_ucl": {"indices": self.mr_hits,
                              "run_ids": [self.points[i].run_id for i in self.mr_hits]},
            "ewma": self.ewma.to_dict() if self.ewma else None,
            "signal": has_signal(self),
            "points": [{"run_id": p.run_id, "serial": p.serial, "station": p.station,
                        "started_at": p.started_at.isoformat(), "value": float(p.value),
                        "expanded_uncertainty": float(p.expanded_uncertainty),
                        "moving_range": None if np.isnan(m) else float(m)}
                       for p, m in zip(self.points, mr, strict=True)],
        }


def has_signal(result: SpcResult, *, last: int | None = None, include_mr: bool = False
               ) -> bool:
    """Whether ``spc`` should exit 1: a selected Nelson rule or the EWMA fired.

    Parameters
    ----------
    result : SpcResult
    last : int, optional
        Count only hits among the newest ``last`` runs (a line gating each new unit against
        a frozen baseline does not want last week's hits to fail today's unit).
    include_mr : bool
        Also gate on the moving-range chart. Off by default: with UCL = 3.267·MR̄ each
        moving range of in-control normal data exceeds it with probability 0.009 (a third
        of 50-run series show one), and the MR chart adds little to the individuals chart
        (Rigdon, Cruthis & Champ 1994); it is shown, not gated.
    """
    first = 0 if last is None else max(result.n - last, 0)
    hits = [i for found in result.rule_hits.values() for i in found]
    if result.ewma is not None:
        hits += result.ewma.signals
    if include_mr:
        hits += result.mr_hits
    return any(i >= first for i in hits)


def spc_report(
    points: Sequence[SeriesPoint],
    *,
    parameter: str | None = None,
    limits_from: str = "data",
    baseline: Mapping[str, object] | Baseline | None = None,
    rules: Iterable[int] | str = DEFAULT_RULES,
    ewma: EwmaSettings | None = None,
    include_reference: bool = False,
    confidence: float = 0.95,
) -> SpcResult:
    """Capability, I-MR chart, Nelson rules and EWMA of one parameter's stored results.

    Parameters
    ----------
    points : sequence of SeriesPoint
        The parameter's results (any order; sorted by ``started_at``). Reference units are
        left out unless ``include_reference``; the store leaves out aborted runs.
    parameter : str, optional
        Its name, for the report; checked against a baseline's (default: the baseline's
        name, else "value").
    limits_from : {"data", "baseline"}
        Trial limits from this series, or the frozen ``baseline``'s.
    baseline : dict or Baseline or None
        A frozen baseline (``Baseline.to_dict()`` form); needed for ``limits_from="baseline"``.
    rules : iterable of int or str
        Nelson rules to apply (default 1, 2, 5, 6; ``"all"`` for 1–8).
    ewma : EwmaSettings or None
        λ and L of the EWMA chart (default λ = 0.2, L = 3); its centre and σ are those of
        the I chart.
    confidence : float
        Level of the capability intervals.

    Raises
    ------
    InputError
        Fewer than 2 runs, an unknown ``limits_from``, a missing or mismatched baseline,
        mixed units, bad rules.
    """
    selected = parse_rules(rules)
    frozen_in = (baseline if isinstance(baseline, Baseline) or baseline is None
                 else Baseline.from_dict(baseline))
    parameter = parameter or (frozen_in.parameter if frozen_in else "value")
    runs = ordered(points, include_reference=include_reference)
    excluded = len(points) - len(runs)
    if len(runs) < 2:
        raise InputError(f"spc for '{parameter}' needs at least 2 runs, got {len(runs)}")
    unit = single_unit(runs)
    x = values_of(runs)
    frozen = _baseline(frozen_in, parameter, unit)
    if limits_from == "baseline":
        if frozen is None:
            raise InputError(f"spc for '{parameter}': limits from a baseline, but none is "
                             "frozen (freeze one from at least 25 runs first)")
        limits = imr_limits_from(frozen.centre, frozen.mr_bar, n=frozen.n, source="baseline")
    elif limits_from == "data":
        limits = imr_limits(x)
    else:
        raise InputError(f"limits_from '{limits_from}' is not 'data' or 'baseline'")
    lower, upper = spec_limits(runs)
    typical = typical_u([p.expanded_uncertainty for p in runs])
    flat = no_spread_sentence(x, unit=unit, expanded_uncertainty=typical)
    if flat:  # σ = 0: nothing to chart, no rule or index is defined; said in words
        return SpcResult(
            parameter=parameter, unit=unit, points=runs, values=x, excluded_reference=excluded,
            lower_limit=lower, upper_limit=upper, nominal=runs[-1].nominal, capability=None,
            capability_note=flat, limits=limits, baseline=frozen if limits_from == "baseline"
            else None, rules=selected, rule_hits={r: [] for r in selected}, mr_hits=[],
            ewma=None, typical_u=typical, no_spread=flat)
    cap, note = None, ""
    if lower is None and upper is None:
        note = "no specification limits on these results"
    else:
        try:
            cap = capability(x, lower_limit=lower, upper_limit=upper, confidence=confidence)
        except InputError as exc:
            note = str(exc)
    hits = nelson_rules(x, centre=limits.centre, sigma=limits.sigma, rules=selected)
    mr = moving_ranges(x)
    mr_hits = [int(i) + 1 for i in np.flatnonzero(mr > limits.mr_ucl)]
    chart = ewma_chart(x, centre=limits.centre, sigma=limits.sigma,
                       settings=ewma if ewma is not None else EwmaSettings())
    return SpcResult(
        parameter=parameter, unit=unit, points=runs, values=x, excluded_reference=excluded,
        lower_limit=lower, upper_limit=upper, nominal=runs[-1].nominal, capability=cap,
        capability_note=note, limits=limits, baseline=frozen if limits_from == "baseline"
        else None, rules=selected, rule_hits=hits, mr_hits=mr_hits, ewma=chart,
        typical_u=typical,
    )


def no_spread_sentence(values: NDArray[np.float64], *, unit: str,
                       expanded_uncertainty: float) -> str:
    """The plain sentence for a series whose values are all equal (σ = 0), else "" (a frozen
    baseline always has a spread: freezing refuses a series that does not vary).

    ``all 5 values equal 27.24 Hz: no spread to chart or judge capability on``
    """
    if values.size == 0 or np.ptp(values) > 0:
        return ""
    unit_text = f" {unit}" if unit else ""
    return (f"all {values.size} values equal {value_text(float(values[0]), expanded_uncertainty)}"
            f"{unit_text}: no spread to chart or judge capability on")


def value_text(value: float, expanded_uncertainty: float) -> str:
    """A value at the decimal place its typical U allows (4 significant digits without U)."""
    return at_u(value, expanded_uncertainty) if expanded_uncertainty > 0 else f"{value:.4g}"


def _baseline(frozen: Baseline | None, parameter: str, unit: str) -> Baseline | None:
    if frozen is None:
        return None
    if frozen.parameter != parameter:
        raise InputError(f"the baseline is for '{frozen.parameter}', not '{parameter}'")
    if frozen.unit != unit:
        raise InputError(f"the baseline's unit '{frozen.unit}' is not the series' '{unit}'")
    return frozen
