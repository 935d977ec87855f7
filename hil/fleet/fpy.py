"""First-pass yield per station and per day (docs/fleet.md §5)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import date, datetime

from hil.errors import InputError
from hil.fleet.series import RunRecord


@dataclass(frozen=True, slots=True, kw_only=True)
class YieldRow:
    """First passes of one group: how many units, how each came out, and the yield."""

    station: str | None
    day: date | None
    units: int
    passed: int
    marginal: int
    failed: int

    @property
    def first_pass_yield(self) -> float:
        """PASS on the first pass / units (MARGINAL does not count as a pass)."""
        return self.passed / self.units if self.units else float("nan")

    def to_dict(self) -> dict[str, object]:
        """JSON-ready."""
        return {"station": self.station, "day": self.day.isoformat() if self.day else None,
                "units": self.units, "passed": self.passed, "marginal": self.marginal,
                "failed": self.failed, "first_pass_yield": self.first_pass_yield}


@dataclass(frozen=True, slots=True, kw_only=True)
class UnitPass:
    """A unit's first pass: of a gimbal, each axis's first pass together."""

    serial: str
    station: str  # where its first axis was calibrated
    started_at: datetime
    outcome: str  # the worst of its axes' (PASS, MARGINAL, then anything else)
    attempt: int
    aborted: bool
    is_reference: bool
    axis: str  # its axes, comma-separated


def _rank(outcome: str) -> int:
    return {"PASS": 0, "MARGINAL": 1}.get(outcome.upper(), 2)


def first_passes(runs: Sequence[RunRecord], *, include_aborted: bool = False,
                 include_reference: bool = False) -> list[UnitPass]:
    """Each unit's first pass: per axis, its run with the lowest attempt number (earliest
    on a tie); a unit of several axes (a gimbal under one serial) passes first time only
    when each axis did, so it takes the worst of its axes' first passes.

    Aborted runs and reference (golden) units are left out unless asked, so a unit whose
    first attempt was aborted is judged on its first completed one.
    """
    best: dict[tuple[str, str], RunRecord] = {}
    for run in runs:
        if (run.aborted and not include_aborted) or (run.is_reference and not include_reference):
            continue
        key = (run.serial, run.axis)
        held = best.get(key)
        if held is None or (run.attempt, run.started_at) < (held.attempt, held.started_at):
            best[key] = run
    by_unit: dict[str, list[RunRecord]] = {}
    for (serial, _), run in sorted(best.items()):
        by_unit.setdefault(serial, []).append(run)
    passes = []
    for serial, axes in by_unit.items():
        first = min(axes, key=lambda r: r.started_at)
        worst = max(axes, key=lambda r: _rank(r.outcome))
        passes.append(UnitPass(serial=serial, station=first.station, started_at=first.started_at,
                               outcome=worst.outcome, attempt=max(r.attempt for r in axes),
                               aborted=any(r.aborted for r in axes),
                               is_reference=any(r.is_reference for r in axes),
                               axis=",".join(r.axis for r in axes)))
    return sorted(passes, key=lambda r: (r.started_at, r.serial))


def first_pass_yield(runs: Sequence[RunRecord], *, by: str = "station",
                     include_aborted: bool = False,
                     include_reference: bool = False) -> list[YieldRow]:
    """First-pass yield grouped ``by`` "station", "day" or "station_day".

    Parameters
    ----------
    runs : sequence of RunRecord
        Runs of any units; each unit's history should be complete (the lowest attempt wins).
    by : str
        Grouping; a unit counts for the station and day of its first pass.

    Returns
    -------
    list of YieldRow
        Sorted by station then day.
    """
    if by not in ("station", "day", "station_day"):
        raise InputError(f"yield grouping '{by}' is not station, day or station_day")
    groups: dict[tuple[str | None, date | None], list[UnitPass]] = {}
    for run in first_passes(runs, include_aborted=include_aborted,
                            include_reference=include_reference):
        key = (run.station if by != "day" else None,
               run.started_at.date() if by != "station" else None)
        groups.setdefault(key, []).append(run)
    rows = []
    for (station, day), members in groups.items():
        outcomes = [m.outcome.upper() for m in members]
        rows.append(YieldRow(station=station, day=day, units=len(members),
                             passed=outcomes.count("PASS"), marginal=outcomes.count("MARGINAL"),
                             failed=len(members) - outcomes.count("PASS")
                             - outcomes.count("MARGINAL")))
    return sorted(rows, key=lambda r: (r.station or "", r.day or date.min))


@dataclass(frozen=True, slots=True, kw_only=True)
class YieldResult:
    """First-pass yield rows: :meth:`table` for a person, :meth:`to_json` for tools."""

    by: str
    rows: list[YieldRow]

    def table(self) -> str:
        """One line per group."""
        lines = [f"first-pass yield per {self.by.replace('_', ' and ')}",
                 f"{'station':<12}{'day':<12}{'units':>6}{'PASS':>6}{'MARG.':>6}{'FAIL':>6}"
                 f"{'yield':>9}"]
        for r in self.rows:
            lines.append(f"{r.station or '':<12}{r.day.isoformat() if r.day else '':<12}"
                         f"{r.units:>6}{r.passed:>6}{r.marginal:>6}{r.failed:>6}"
                         f"{100 * r.first_pass_yield:>8.1f}%")
        return "\n".join(lines)

    def to_json(self) -> dict[str, object]:
        """JSON-ready."""
        return {"by": self.by, "rows": [r.to_dict() for r in self.rows]}


def yield_table(runs: Sequence[RunRecord], *, by: str = "station",
                include_aborted: bool = False, include_reference: bool = False) -> YieldResult:
    """:func:`first_pass_yield` as a result with a table and JSON."""
    return YieldResult(by=by, rows=first_pass_yield(runs, by=by,
                                                    include_aborted=include_aborted,
                                                    include_reference=include_reference))
