"""Stop when the uncertainty is reached: run a protocol's excitation again until every
result's expanded uncertainty is at most a stated fraction of its tolerance, or a maximum
number of runs.

A protocol table opts in with ``stop_at_u_fraction`` (e.g. 0.25: ``U ≤ ¼`` of the
tolerance half-width ``(upper − lower)/2``), ``max_runs`` (default 3) and optionally
``stop_results`` (the results judged, comma-separated; default every result of the
protocol). The judged U is
the certificate's: the method's line from the bias map and the profile's allowance are
added first (:func:`hil.measurement.with_method_terms`). Runs cannot shrink those, nor the
other Type B lines: when they alone exceed the target the reason says so. A clean unit
stops after one run; a noisy one runs again and its certificate says why
(:attr:`StopDecision.reason`).

Repeated runs are pooled as independent repeats of one measurement: the mean value, each
Type A line divided by √n with its degrees of freedom summed, the Type B lines (inputs
that every run shares: earlier protocols' results) kept as the first run states them, as
are Type A lines that carry an earlier result into every run (``shared``).
:func:`run_repeated` is the protocols' one shape: run, pool, say why in the details.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Generic, TypeVar

from hil.calibration import CalibrationRun
from hil.config import ConfigTable
from hil.details import RunsFields
from hil.errors import IdentificationError, ProfileError
from hil.identify.estimate import Component, Estimate, with_budget
from hil.measurement import MethodBias, MethodBiasMap, with_method_terms
from hil.profile import MeasurementSpec

KEYS = ("stop_at_u_fraction", "max_runs", "stop_results")
T = TypeVar("T")


@dataclass(frozen=True, slots=True, kw_only=True)
class StopRule:
    """Run again while a result's U exceeds ``fraction`` of its tolerance half-width."""

    fraction: float
    max_runs: int
    results: tuple[str, ...] | None  # judged results; None: all of the protocol's
    table: ConfigTable | None = dataclasses.field(default=None, compare=False)  # for errors

    @classmethod
    def from_settings(cls, settings: ConfigTable) -> StopRule | None:
        """The rule from a protocol's table (``stop_at_u_fraction``, ``max_runs``); ``None``
        when the table does not ask for one (one run, as always).

        Raises
        ------
        ProfileError
            ``stop_at_u_fraction`` not positive, or ``max_runs`` below 1.
        """
        if "stop_at_u_fraction" not in settings:
            return None
        fraction = settings.positive("stop_at_u_fraction")
        runs = settings.integer("max_runs", 3)
        if runs < 1:
            raise settings.error("max_runs", f"must be at least 1, not {runs}")
        results = (tuple(n.strip() for n in settings.string("stop_results").split(",")
                         if n.strip()) if "stop_results" in settings else None)
        return cls(fraction=fraction, max_runs=runs, results=results, table=settings)

    def check(self, found: Sequence[str]) -> None:
        """Refuse ``stop_results`` naming a result the protocol does not give.

        Raises
        ------
        ProfileError
            A judged result is not among ``found``, the names of the protocol's results.
        """
        unknown = [name for name in self.results or () if name not in found]
        if not unknown:
            return
        message = (f"{', '.join(map(repr, unknown))} is not a result of this protocol "
                   f"(its results: {', '.join(found)})")
        if self.table is None:
            raise ProfileError(f"'stop_results': {message}")
        raise self.table.error("stop_results", message)

    @staticmethod
    def refuse(settings: ConfigTable, why: str) -> None:
        """Refuse the rule's keys in a table whose protocol cannot pool repeated runs.

        Raises
        ------
        ProfileError
            One of :data:`KEYS` is in ``settings``; the line says ``why``.
        """
        for key in KEYS:
            if key in settings:
                raise settings.error(key, f"no stop rule here: {why}")


@dataclass(frozen=True, slots=True, kw_only=True)
class StopDecision:
    """Whether to run again, and the sentence the certificate carries."""

    again: bool
    reason: str
    runs: int


def target_expanded_u(spec: MeasurementSpec, fraction: float) -> float:
    """``fraction`` of the tolerance half-width ``(upper − lower)/2`` of ``spec``."""
    return fraction * (spec.upper_limit - spec.lower_limit) / 2


def same_lines(runs: Sequence[Estimate]) -> bool:
    """Whether the runs' budgets have the same lines (number and kinds, in one order)."""
    kinds = [[line.kind for line in r.components()] for r in runs]
    return all(k == kinds[0] for k in kinds)


def pooled(runs: Sequence[Estimate], *, shared: Sequence[str] = ()) -> Estimate:
    """Independent repeats of one measurement as one estimate.

    Parameters
    ----------
    runs : sequence of Estimate
        The same result from each run (same name, unit and budget lines, in one order).
    shared : sequence of str
        Beginnings of the sources of Type A lines that carry an earlier result's u into
        every run (the same error in each): kept as the first run states them.

    Returns
    -------
    Estimate
        The mean value; Type A lines ``u/√n`` (root sum of squares over ``n``) with the
        degrees of freedom summed; Type B and shared lines of the first run (shared inputs
        do not average out). One run is returned as is.

    Raises
    ------
    IdentificationError
        The runs' budgets differ in their number or kinds of lines.
    """
    if len(runs) == 1:
        return runs[0]
    n = len(runs)
    first = runs[0]
    budgets = [r.components() for r in runs]
    if not same_lines(runs):
        raise IdentificationError(f"{first.name}: the {n} runs' uncertainty budgets differ "
                                  "in their lines, so the runs cannot be pooled")
    lines: list[Component] = []
    for i, line in enumerate(budgets[0]):
        if line.kind == "B" or line.source.startswith(tuple(shared)):
            lines.append(line)
            continue
        same = [budget[i] for budget in budgets]
        u = math.sqrt(sum(c.contribution ** 2 for c in same)) / n
        lines.append(dataclasses.replace(
            line, standard_uncertainty=u, sensitivity=1.0, unit=first.unit,
            dof=sum(c.dof for c in same), source=f"{line.source}, mean of {n} runs"))
    value = math.fsum(r.value for r in runs) / n
    return with_budget(dataclasses.replace(first, cramer_rao_std=None), lines, value=value)


def floor_expanded_u(estimate: Estimate, *, shared: Sequence[str] = ()) -> float:
    """The U that no number of runs shrinks: Type B and shared lines alone (:func:`pooled`)."""
    kept = [line for line in estimate.components()
            if line.kind == "B" or line.source.startswith(tuple(shared))]
    return with_budget(estimate, kept, value=estimate.value).expanded_uncertainty if kept else 0.0


def decide(estimates: Mapping[str, Estimate], specs: Mapping[str, MeasurementSpec],
           method_bias: MethodBiasMap, rule: StopRule, *, runs: int,
           shared: Sequence[str] = (),
           lines: Callable[[str], MethodBias | None] | None = None) -> StopDecision:
    """Run again? Only while some result's certificate U exceeds its target and runs remain.

    Parameters
    ----------
    estimates : mapping of str to Estimate
        The protocol's results so far (pooled over ``runs``), as its analysis gives them.
    specs : mapping of str to MeasurementSpec
        Their declarations (limits); results without one are not judged here.
    method_bias : MethodBiasMap
        The calibration's map (its lines are part of the U judged).
    rule : StopRule
        The profile's rule.
    runs : int
        Runs made so far.
    shared : sequence of str
        Type A lines every run shares (see :func:`pooled`).
    lines : callable, optional
        Each result's method line, as the certificate will add it (its acquisition path
        and variant, :meth:`hil.calibration.CalibrationRun.method_line`); default: the
        map's main line.

    Returns
    -------
    StopDecision
        ``again`` and the reason: which result's U was above its target (and, when the
        lines runs cannot shrink exceed the target alone, their U), or that every U was
        below, or that the maximum number of runs was reached first.
    """
    above = []
    for name, estimate in estimates.items():
        spec = specs.get(name)
        if spec is None or (rule.results is not None and name not in rule.results):
            continue
        line = method_bias.entries.get(name) if lines is None else lines(name)
        final = with_method_terms(estimate, spec, line)
        target = target_expanded_u(spec, rule.fraction)
        if final.expanded_uncertainty > target:
            floor = floor_expanded_u(final, shared=shared)
            above.append(f"{name} U = {final.expanded_uncertainty:.2g} > {target:.2g} "
                         f"{spec.unit}".rstrip() + (
                             f" (runs cannot take it below {floor:.2g}: Type B and shared "
                             "lines)" if floor > target else ""))
    if not above:
        return StopDecision(again=False, runs=runs, reason=(
            f"every U ≤ {rule.fraction:g} × the tolerance half-width after {runs} run"
            f"{'s' if runs > 1 else ''}"))
    if runs >= rule.max_runs:
        return StopDecision(again=False, runs=runs, reason=(
            f"max_runs = {rule.max_runs} reached with {'; '.join(above)}"))
    return StopDecision(again=True, runs=runs, reason=(
        f"run {runs + 1} of at most {rule.max_runs}: after {runs} "
        f"{'runs' if runs > 1 else 'run'}, {'; '.join(above)}"))


def repeat_until(run_once: Callable[[], Mapping[str, Estimate]], *,
                 specs: Mapping[str, MeasurementSpec], method_bias: MethodBiasMap,
                 rule: StopRule | None, shared: Sequence[str] = (),
                 lines: Callable[[str], MethodBias | None] | None = None
                 ) -> tuple[dict[str, Estimate], StopDecision]:
    """Run a protocol's measurement once, then again while :func:`decide` asks for it.

    Parameters
    ----------
    run_once : callable
        Runs the excitation once and returns its results by name.
    specs : mapping of str to MeasurementSpec
        The results' declarations.
    method_bias : MethodBiasMap
        The calibration's map.
    rule : StopRule or None
        The profile's rule; ``None``: one run.
    shared : sequence of str
        Type A lines every run shares (see :func:`pooled`).

    Returns
    -------
    results : dict of str to Estimate
        Pooled over the runs made (:func:`pooled`).
    decision : StopDecision
        The last decision: why the protocol stopped, after how many runs.

    Raises
    ------
    ProfileError
        The rule's ``stop_results`` names a result the first run did not give.
    """
    runs = [dict(run_once())]
    now = runs[0]
    if rule is None:
        return now, StopDecision(again=False, runs=1, reason="one run (no stop rule)")
    rule.check(list(now))
    while True:
        decision = decide(now, specs, method_bias, rule, runs=len(runs), shared=shared,
                          lines=lines)
        if not decision.again:
            return now, decision
        runs.append(dict(run_once()))
        other = [name for name in runs[0] if not same_lines([r[name] for r in runs])]
        if other:  # e.g. a detection in one run, only a bound in another: no repeat
            return now, StopDecision(again=False, runs=len(runs) - 1, reason=(
                f"run {len(runs)} left out: its {', '.join(other)} has other budget lines "
                f"than run 1's, so it is no repeat of the same measurement ({decision.reason})"))
        now = {name: pooled([r[name] for r in runs], shared=shared) for name in runs[0]}


@dataclass(frozen=True, slots=True, kw_only=True)
class Repeated(Generic[T]):
    """A protocol's runs under its rule: pooled results, the first run's analysis."""

    estimates: dict[str, Estimate]  # pooled over the runs (:func:`pooled`)
    first: T  # the first run's analysis, for the certificate's details
    decision: StopDecision

    def details(self) -> RunsFields:
        """The certificate's lines: how many runs, and why the protocol stopped
        (``RunDetails(**repeated.details(), ...)``)."""
        return {"runs": self.decision.runs, "stop_rule": self.decision.reason}


def run_repeated(run_once: Callable[[], T], results: Callable[[T], Mapping[str, Estimate]],
                 *, rule: StopRule | None, calibration: CalibrationRun,
                 shared: Sequence[str] = (),
                 acquisition: Callable[[T], str | None] | None = None,
                 variant: Callable[[T], str | None] | None = None) -> Repeated[T]:
    """A protocol's excitation and analysis, run again while its rule asks for it.

    Parameters
    ----------
    run_once : callable
        Runs the excitation once (moves included) and returns its analysis.
    results : callable
        The analysis's results by name (the estimates pooled and judged).
    rule : StopRule or None
        The profile's rule; ``None``: one run.
    calibration : CalibrationRun
        The calibration in progress: the profile's declarations and the method map.
    shared : sequence of str
        Type A lines every run shares (see :func:`pooled`).
    acquisition, variant : callable, optional
        From the first run's analysis: the path its recording came over and the method's
        variant, as the protocol records its results with them
        (:meth:`CalibrationRun.record`), so that each run's U is judged with the method
        line its certificate will state. Default: the map's main line.

    Returns
    -------
    Repeated
        Pooled results, the first run's analysis and the last decision.
    """
    analyses: list[T] = []

    def once() -> Mapping[str, Estimate]:
        analyses.append(run_once())
        return results(analyses[-1])

    def line(name: str) -> MethodBias | None:
        first = analyses[0]
        return calibration.method_line(
            name, acquisition=None if acquisition is None else acquisition(first),
            variant=None if variant is None else variant(first))

    estimates, decision = repeat_until(once, specs=calibration.profile.measurements,
                                       method_bias=calibration.method_bias, rule=rule,
                                       shared=shared, lines=line)
    return Repeated(estimates=estimates, first=analyses[0], decision=decision)
