"""First-pass yield per station and per day (docs/fleet.md §5): of the units, of the
gimbals (a gimbal passes first time when its first gimbal certificate is PASS, which it is
only when each of its axes passed) and of each kind of axis (each axis's first run, never
pooled across axes or part numbers)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import date, datetime
from typing import Protocol

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
    kind: str | None = None  # a gimbal's part number, or a kind of axis ("GMB-2 elevation")

    @property
    def first_pass_yield(self) -> float:
        """PASS on the first pass / units (MARGINAL does not count as a pass)."""
        return self.passed / self.units if self.units else float("nan")

    def to_dict(self) -> dict[str, object]:
        """JSON-ready."""
        return {"station": self.station, "day": self.day.isoformat() if self.day else None,
                "kind": self.kind, "units": self.units, "passed": self.passed,
                "marginal": self.marginal, "failed": self.failed,
                "first_pass_yield": self.first_pass_yield}


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


class GimbalRecord(Protocol):
    """A gimbal certificate (for the gimbals' first-pass yield): the results store's
    ``StoredGimbal`` has these attributes."""

    @property
    def serial(self) -> str: ...
    @property
    def part_number(self) -> str: ...
    @property
    def station(self) -> str: ...
    @property
    def issued_at(self) -> datetime: ...
    @property
    def outcome(self) -> str: ...


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
                     include_aborted: bool = False, include_reference: bool = False,
                     gimbals: Sequence[GimbalRecord] = ()) -> list[YieldRow]:
    """First-pass yield grouped ``by`` "station", "day" or "station_day".

    Parameters
    ----------
    runs : sequence of RunRecord
        Runs of any units; each unit's history should be complete (the lowest attempt wins).
    by : str
        Grouping; a unit counts for the station and day of its first pass.
    gimbals : sequence of GimbalRecord
        Each gimbal's first gimbal certificate: a serial among them is judged by it (its
        station and issue time) instead of by its axes' first runs.

    Returns
    -------
    list of YieldRow
        Sorted by station then day.
    """
    _check_grouping(by)
    first = {g.serial: g for g in gimbals}
    passes = [(p.station, p.started_at, p.outcome) if p.serial not in first else
              (first[p.serial].station, first[p.serial].issued_at, first[p.serial].outcome)
              for p in first_passes(runs, include_aborted=include_aborted,
                                    include_reference=include_reference)]
    return _grouped([(None, *p) for p in passes], by)


def gimbal_first_pass_yield(gimbals: Sequence[GimbalRecord], *,
                            by: str = "station") -> list[YieldRow]:
    """First-pass yield of gimbals per part number, grouped ``by`` "station", "day" or
    "station_day": a gimbal passes first time when its first gimbal certificate is PASS
    (the worst of its axes': PASS only when each axis passed).

    Parameters
    ----------
    gimbals : sequence of GimbalRecord
        Gimbal certificates; each serial's earliest (issue time) is its first pass.
    """
    _check_grouping(by)
    first: dict[str, GimbalRecord] = {}
    for gimbal in sorted(gimbals, key=lambda g: g.issued_at):
        first.setdefault(gimbal.serial, gimbal)
    return _grouped([(g.part_number, g.station, g.issued_at, g.outcome)
                     for g in first.values()], by)


def axis_first_pass_yield(runs: Sequence[RunRecord], *, by: str = "station",
                          include_aborted: bool = False,
                          include_reference: bool = False) -> list[YieldRow]:
    """First-pass yield of each kind of axis (its part number, or its unit type, and its
    axis: never pooled), grouped ``by`` "station", "day" or "station_day": each axis of
    each unit by its first run (the lowest attempt, earliest on a tie)."""
    _check_grouping(by)
    best: dict[tuple[str, str], RunRecord] = {}
    for run in runs:
        if (run.aborted and not include_aborted) or (run.is_reference and not include_reference):
            continue
        key = (run.serial, run.axis)
        held = best.get(key)
        if held is None or (run.attempt, run.started_at) < (held.attempt, held.started_at):
            best[key] = run
    return _grouped([(axis_kind(r), r.station, r.started_at, r.outcome)
                     for r in best.values()], by)


def axis_kind(run: RunRecord) -> str:
    """The kind of axis a run is of: "PN AXIS" for an axis of a gimbal whose certificate
    is stored, else its unit type (and axis, when the type does not name it)."""
    # the store's runs carry these two; any other RunRecord is a unit of its own kind
    part_number = str(getattr(run, "part_number", "") or "")
    unit_type = str(getattr(run, "unit_type", "") or "")
    if part_number:
        return f"{part_number} {run.axis}"
    if run.axis and run.axis not in unit_type:
        return f"{unit_type}, {run.axis}" if unit_type else run.axis
    return unit_type


def _check_grouping(by: str) -> None:
    if by not in ("station", "day", "station_day"):
        raise InputError(f"yield grouping '{by}' is not station, day or station_day")


def _grouped(passes: Sequence[tuple[str | None, str, datetime, str]],
             by: str) -> list[YieldRow]:
    """Rows of first passes (kind, station, when, outcome), per kind and ``by`` group."""
    groups: dict[tuple[str | None, str | None, date | None], list[str]] = {}
    for of_kind, station, when, outcome in passes:
        key = (of_kind, station if by != "day" else None,
               when.date() if by != "station" else None)
        groups.setdefault(key, []).append(outcome.upper())
    rows = []
    for (kind, where, day), outcomes in groups.items():
        rows.append(YieldRow(station=where, day=day, units=len(outcomes), kind=kind,
                             passed=outcomes.count("PASS"), marginal=outcomes.count("MARGINAL"),
                             failed=len(outcomes) - outcomes.count("PASS")
                             - outcomes.count("MARGINAL")))
    return sorted(rows, key=lambda r: (r.kind or "", r.station or "", r.day or date.min))


@dataclass(frozen=True, slots=True, kw_only=True)
class YieldResult:
    """First-pass yield rows: :meth:`table` for a person, :meth:`to_json` for tools."""

    by: str
    rows: list[YieldRow]  # the units (a gimbal by its first gimbal certificate)
    gimbals: list[YieldRow] = field(default_factory=list)  # per part number
    axes: list[YieldRow] = field(default_factory=list)  # per kind of axis

    def table(self) -> str:
        """One line per group: the units; then, when the store holds gimbals (or units of
        several axes), the gimbals per part number and each kind of axis."""
        lines = [f"first-pass yield per {self.by.replace('_', ' and ')}"]
        # a unit of several axes: its axes' yields too (one-axis units: the same figures)
        several = bool(self.gimbals) or (sum(r.units for r in self.axes)
                                         != sum(r.units for r in self.rows))
        if several:
            lines.append("units (a gimbal by its first gimbal certificate):")
        lines += _rows_table(self.rows, None)
        if self.gimbals:
            lines += ["", "gimbals (passed first time: the first gimbal certificate PASS, "
                          "each axis passed):"]
            lines += _rows_table(self.gimbals, "part number")
        if several and self.axes:
            lines += ["", "axes (each axis's first run, per part number and axis):"]
            lines += _rows_table(self.axes, "axis")
        return "\n".join(lines)

    def to_json(self) -> dict[str, object]:
        """JSON-ready."""
        return {"by": self.by, "rows": [r.to_dict() for r in self.rows],
                "gimbals": [r.to_dict() for r in self.gimbals],
                "axes": [r.to_dict() for r in self.axes]}


def _rows_table(rows: Sequence[YieldRow], kind: str | None) -> list[str]:
    width = max([len(kind or ""), *(len(r.kind or "") for r in rows)]) + 2 if kind else 0
    lines = [f"{'station':<12}{'day':<12}{kind or '':<{width}}{'units':>6}{'PASS':>6}"
             f"{'MARG.':>6}{'FAIL':>6}{'yield':>9}"]
    for r in rows:
        lines.append(f"{r.station or '':<12}{r.day.isoformat() if r.day else '':<12}"
                     f"{(r.kind or '') if kind else '':<{width}}"
                     f"{r.units:>6}{r.passed:>6}{r.marginal:>6}{r.failed:>6}"
                     f"{100 * r.first_pass_yield:>8.1f}%")
    return lines


def yield_table(runs: Sequence[RunRecord], *, by: str = "station",
                include_aborted: bool = False, include_reference: bool = False,
                gimbals: Sequence[GimbalRecord] = ()) -> YieldResult:
    """:func:`first_pass_yield` (the units), :func:`gimbal_first_pass_yield` of
    ``gimbals`` (each serial's first gimbal certificate) and :func:`axis_first_pass_yield`
    as a result with a table and JSON."""
    flags = {"include_aborted": include_aborted, "include_reference": include_reference}
    return YieldResult(by=by, rows=first_pass_yield(runs, by=by, gimbals=gimbals, **flags),
                       gimbals=gimbal_first_pass_yield(gimbals, by=by),
                       axes=axis_first_pass_yield(runs, by=by, **flags))
