"""Read the store: the series statistics are computed on, the fleet's units, one unit's
history, and the frozen SPC baselines.

``result_series`` and :class:`StoredResult` are the interface the fleet statistics
(``hil.fleet``) are written against: keep their names and fields.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any, TypeVar

from sqlalchemy import Select, and_, delete, func, insert, select

from hil.store.engine import Store
from hil.store.schema import gimbals, results, runs, spc_baselines

NO_PART_NUMBER = "none"  # --part-number none: the units without a stored gimbal certificate
_Query = TypeVar("_Query", bound=Select[*tuple[Any, ...]])


@dataclass(frozen=True, slots=True)
class StoredResult:
    """One stored result of one run, with what statistics need to filter and judge it."""

    run_id: str
    certificate_id: str
    serial: str
    station: str
    started_at: datetime
    value: float
    standard_uncertainty: float
    expanded_uncertainty: float
    unit: str
    nominal: float | None
    lower_limit: float | None
    upper_limit: float | None
    outcome: str
    is_reference: bool


@dataclass(frozen=True, slots=True, order=True)
class Kind:
    """The kind of unit a result was measured on: its unit type and axis, and the part
    number of the gimbal it is an axis of ("" for a unit without a stored gimbal
    certificate). Statistics never pool results of different kinds (an azimuth and an
    elevation inertia are two series, and so are two part numbers' elevations)."""

    unit_type: str
    axis: str
    part_number: str = ""

    def __str__(self) -> str:
        shown = (self.unit_type if self.axis in self.unit_type
                 else f"{self.unit_type}, {self.axis}")
        return f"part number {self.part_number}, {shown}" if self.part_number else shown


@dataclass(frozen=True, slots=True)
class StoredGimbal:
    """A stored gimbal certificate: identity, verdict, when, and where its axes ran."""

    certificate_id: str
    serial: str
    part_number: str
    revision: str
    outcome: str
    issued_at: datetime
    station: str  # the station of its first axis's stored run ("" when none is stored)
    axes: tuple[str, ...]
    axis_certificates: tuple[str, ...]  # each axis's certificate id, in ``axes`` order


@dataclass(frozen=True, slots=True)
class RunSummary:
    """A stored run, as ``units`` and ``history`` list it."""

    run_id: str
    certificate_id: str
    serial: str
    unit_type: str
    station: str
    operator: str
    started_at: datetime
    ended_at: datetime
    outcome: str
    aborted: bool
    attempt: int
    is_reference: bool
    axis: str = ""
    runs_of_unit: int = 1
    part_number: str = ""  # of the gimbal the run is an axis of ("": none stored)


def utc(moment: datetime) -> datetime:
    """``moment`` as an aware UTC time (SQLite hands back naive ones)."""
    return moment.replace(tzinfo=UTC) if moment.tzinfo is None else moment.astimezone(UTC)


def result_series(
    store: Store,
    name: str,
    *,
    station: str | None = None,
    since: datetime | None = None,
    include_aborted: bool = False,
    include_reference: bool = False,
    kind: Kind | None = None,
    revision: str | None = None,
) -> list[StoredResult]:
    """Every stored value of result ``name``, oldest run first.

    Parameters
    ----------
    store : Store
        An open store.
    name : str
        The result (measurement) name, e.g. ``"inertia_kg_m2"``.
    station : str, optional
        Only runs of this station id.
    since : datetime, optional
        Only runs started at or after it (naive times are taken as UTC).
    include_aborted : bool
        Keep aborted runs (left out of statistics by default).
    include_reference : bool
        Keep runs of reference (golden) units (left out by default).
    kind : Kind, optional
        Only runs of this unit type and axis, of gimbals of its part number (of serials
        without a stored gimbal certificate when its part number is "") (see
        :func:`result_kinds`).
    revision : str, optional
        Only gimbals of this revision (of ``kind``'s part number).

    Returns
    -------
    list of StoredResult
        Ordered by ``started_at`` (then run id).
    """
    query = (
        select(
            runs.c.run_id, runs.c.certificate_id, runs.c.serial, runs.c.station,
            runs.c.started_at, results.c.value, results.c.standard_uncertainty,
            results.c.expanded_uncertainty, results.c.unit, results.c.nominal,
            results.c.lower_limit, results.c.upper_limit, results.c.outcome,
            runs.c.is_reference,
        )
        .join(runs, runs.c.run_id == results.c.run_id)
        .where(results.c.name == name)
        .order_by(runs.c.started_at, runs.c.run_id)
    )
    query = _narrowed(query, station=station, since=since)
    if not include_aborted:
        query = query.where(runs.c.aborted.is_(False))
    if not include_reference:
        query = query.where(runs.c.is_reference.is_(False))
    if kind is not None:
        query = query.where(runs.c.unit_type == kind.unit_type, runs.c.axis == kind.axis)
        if kind.part_number:
            query = of_part_number(query, kind.part_number, revision)
        else:  # a one-axis unit, or a gimbal whose certificate is not stored (yet)
            query = query.where(runs.c.serial.not_in(select(gimbals.c.serial)))
    with store.engine.connect() as connection:
        rows = connection.execute(query).all()
    # positional: the columns are selected in the dataclass's field order (fast for 10⁵ rows)
    return [
        StoredResult(r[0], r[1], r[2], r[3], utc(r[4]), r[5], r[6], r[7], r[8], r[9], r[10],
                     r[11], r[12], bool(r[13]))
        for r in rows
    ]


def result_kinds(
    store: Store,
    name: str,
    *,
    station: str | None = None,
    since: datetime | None = None,
    axis: str | None = None,
    unit_type: str | None = None,
    part_number: str | None = None,
    revision: str | None = None,
) -> dict[Kind, int]:
    """The kinds of unit (unit type, axis, gimbal part number) result ``name`` is stored
    for, with how many runs of each (aborted runs included), narrowed by ``axis``,
    ``unit_type``, ``part_number`` and ``revision`` when given."""
    part = _part_of_serial()
    part_number_of_run = func.coalesce(part.c.part_number, "")
    query = (
        select(runs.c.unit_type, runs.c.axis, part_number_of_run, func.count())
        .join(results, runs.c.run_id == results.c.run_id)
        .outerjoin(part, part.c.serial == runs.c.serial)
        .where(results.c.name == name)
        .group_by(runs.c.unit_type, runs.c.axis, part_number_of_run)
    )
    query = _narrowed(query, station=station, since=since)
    if axis is not None:
        query = query.where(runs.c.axis == axis)
    if unit_type is not None:
        query = query.where(runs.c.unit_type == unit_type)
    if part_number is not None:
        query = of_part_number(query, part_number, revision)
    with store.engine.connect() as connection:
        return {Kind(unit_type, axis, part or ""): int(count)
                for unit_type, axis, part, count in connection.execute(query)}


def of_part_number(query: _Query, part_number: str, revision: str | None = None) -> _Query:
    """``query`` (over ``runs``) kept to the serials with a stored gimbal certificate of
    ``part_number`` (and ``revision``, when given); :data:`NO_PART_NUMBER`: to the serials
    without one (one-axis units)."""
    if part_number == NO_PART_NUMBER:
        return query.where(runs.c.serial.not_in(select(gimbals.c.serial)))
    serials = select(gimbals.c.serial).where(gimbals.c.part_number == part_number)
    if revision is not None:
        serials = serials.where(gimbals.c.revision == revision)
    return query.where(runs.c.serial.in_(serials))


def _part_of_serial() -> Any:
    """Each serial with a stored gimbal certificate and its part number (one row a serial:
    a serial certified under two part numbers, which should not happen, takes the greater)."""
    return (select(gimbals.c.serial, func.max(gimbals.c.part_number).label("part_number"))
            .group_by(gimbals.c.serial).subquery())


def gimbal_certificates(
    store: Store,
    *,
    part_number: str | None = None,
    revision: str | None = None,
    serial: str | None = None,
) -> list[StoredGimbal]:
    """Every stored gimbal certificate, oldest first (issue time, then id), narrowed by
    ``part_number``, ``revision`` and ``serial`` when given; each with the station of its
    first axis's stored run."""
    query = select(gimbals).order_by(gimbals.c.issued_at, gimbals.c.certificate_id)
    if part_number is not None:
        query = query.where(gimbals.c.part_number == part_number)
    if revision is not None:
        query = query.where(gimbals.c.revision == revision)
    if serial is not None:
        query = query.where(gimbals.c.serial == serial)
    with store.engine.connect() as connection:
        rows = connection.execute(query).all()
        wanted = {a.get("certificate_id") for row in rows for a in json.loads(row.axes)}
        stations = dict(connection.execute(
            select(runs.c.certificate_id, runs.c.station)
            .where(runs.c.certificate_id.in_(sorted(w for w in wanted if w)))).all()
        ) if wanted else {}
    found = []
    for row in rows:
        axes = [a for a in json.loads(row.axes) if isinstance(a, dict)]
        ids = tuple(str(a.get("certificate_id") or "") for a in axes)
        found.append(StoredGimbal(
            certificate_id=row.certificate_id, serial=row.serial,
            part_number=row.part_number, revision=row.revision, outcome=row.outcome,
            issued_at=utc(row.issued_at),
            station=next((stations[i] for i in ids if i in stations), ""),
            axes=tuple(str(a.get("axis")) for a in axes), axis_certificates=ids))
    return found


def units(store: Store) -> list[RunSummary]:
    """Every unit's latest run (with how many runs it has), by serial."""
    latest = (
        select(runs.c.serial, func.max(runs.c.started_at).label("last"),
               func.count().label("runs_of_unit"))
        .group_by(runs.c.serial)
        .subquery()
    )
    query = (
        select(*_summary_columns(), latest.c.runs_of_unit)
        .join(latest, and_(runs.c.serial == latest.c.serial,
                           runs.c.started_at == latest.c.last))
        .order_by(runs.c.serial, runs.c.run_id)
    )
    latest_per_axis = (select(runs.c.serial, runs.c.axis, runs.c.outcome)
                       .order_by(runs.c.started_at, runs.c.run_id))
    with store.engine.connect() as connection:
        found = {row[2]: _summary(row, runs_of_unit=int(row[13]))
                 for row in connection.execute(query)}
        axes: dict[str, dict[str, str]] = {}
        for serial, axis, outcome in connection.execute(latest_per_axis):
            axes.setdefault(serial, {})[axis] = outcome
    # two runs started in the same second: the last run id; a gimbal (several axes under one
    # serial): its axes, and the worst of each axis's latest outcome
    return [_of_axes(summary, axes.get(serial, {})) for serial, summary in found.items()]


def gimbal_identities(store: Store) -> dict[str, tuple[str, str]]:
    """Part number and revision of each serial that has a gimbal certificate (its latest);
    a serial without one is a one-axis unit."""
    query = select(gimbals.c.serial, gimbals.c.part_number, gimbals.c.revision).order_by(
        gimbals.c.issued_at, gimbals.c.certificate_id)
    with store.engine.connect() as connection:
        return {serial: (part, revision) for serial, part, revision in connection.execute(query)}


def _of_axes(summary: RunSummary, latest: dict[str, str]) -> RunSummary:
    from dataclasses import replace

    if len(latest) < 2:
        return summary
    ranks = {"PASS": 0, "MARGINAL": 1}
    worst = max(latest.values(), key=lambda outcome: ranks.get(outcome, 2))
    return replace(summary, axis=", ".join(sorted(latest)), outcome=worst)


def history(store: Store, serial: str) -> list[RunSummary]:
    """Every run of one unit, oldest first (runs started in the same second, which the
    certificate's start time cannot tell apart, by their attempt number)."""
    query = (
        select(*_summary_columns())
        .where(runs.c.serial == serial)
        .order_by(runs.c.started_at, runs.c.attempt, runs.c.run_id)
    )
    with store.engine.connect() as connection:
        found = [_summary(row) for row in connection.execute(query)]
    return [_with_count(s, len(found)) for s in found]


def run_summaries(
    store: Store, *, station: str | None = None, since: datetime | None = None,
    part_number: str | None = None, revision: str | None = None,
) -> list[RunSummary]:
    """Every stored run (aborted and reference runs included: each carries its flags),
    oldest first, with the part number of the gimbal it is an axis of; for yields per
    station and day.

    Parameters
    ----------
    store : Store
        An open store.
    station : str, optional
        Only runs of this station id.
    since : datetime, optional
        Only runs started at or after it (naive times are taken as UTC).
    part_number, revision : str, optional
        Only runs of gimbals of this part number (and revision).
    """
    part = _part_of_serial()
    query = (select(*_summary_columns(), part.c.part_number)
             .outerjoin(part, part.c.serial == runs.c.serial)
             .order_by(runs.c.started_at, runs.c.run_id))
    query = _narrowed(query, station=station, since=since)
    if part_number is not None:
        query = of_part_number(query, part_number, revision)
    with store.engine.connect() as connection:
        return [_summary(row, part_number=row[13] or "") for row in connection.execute(query)]


def run_results(store: Store, run_id: str) -> dict[str, dict[str, Any]]:
    """One run's results by name (value, u, U, unit, limits, outcome)."""
    with store.engine.connect() as connection:
        rows = connection.execute(select(results).where(results.c.run_id == run_id))
        return {row.name: dict(row._mapping) for row in rows}


def save_baseline(store: Store, name: str, body: dict[str, Any]) -> None:
    """Freeze (or replace) the SPC baseline ``name``.

    Parameters
    ----------
    store : Store
        An open store.
    name : str
        The baseline's name (e.g. the result it belongs to).
    body : dict
        JSON-serialisable content (control limits, the runs it was built from, …).
    """
    text = json.dumps(body, sort_keys=True)
    with store.engine.begin() as connection:
        connection.execute(delete(spc_baselines).where(spc_baselines.c.name == name))
        connection.execute(
            insert(spc_baselines), [{"name": name, "body": text, "frozen_at": datetime.now(UTC)}]
        )


def load_baseline(store: Store, name: str) -> dict[str, Any] | None:
    """The baseline ``name`` as saved, or ``None`` when none was frozen."""
    with store.engine.connect() as connection:
        row = connection.execute(
            select(spc_baselines.c.body).where(spc_baselines.c.name == name)
        ).first()
    if row is None:
        return None
    body: dict[str, Any] = json.loads(row.body)
    return body


def _narrowed(query: _Query, *, station: str | None, since: datetime | None) -> _Query:
    """``query`` kept to runs of ``station`` started at or after ``since`` (when given)."""
    if station is not None:
        query = query.where(runs.c.station == station)
    if since is not None:
        query = query.where(runs.c.started_at >= utc(since))
    return query


def _summary_columns() -> tuple[Any, ...]:
    return (
        runs.c.run_id, runs.c.certificate_id, runs.c.serial, runs.c.unit_type,
        runs.c.station, runs.c.operator, runs.c.started_at, runs.c.ended_at, runs.c.outcome,
        runs.c.aborted, runs.c.attempt, runs.c.is_reference, runs.c.axis,
    )


def _summary(row: Any, *, runs_of_unit: int = 1, part_number: str = "") -> RunSummary:
    """A row of :func:`_summary_columns`."""
    (run_id, certificate_id, serial, unit_type, station, operator, started_at, ended_at,
     outcome, aborted, attempt, is_reference, axis) = row[:13]
    return RunSummary(
        run_id=run_id, certificate_id=certificate_id, serial=serial, unit_type=unit_type,
        station=station, operator=operator, started_at=utc(started_at),
        ended_at=utc(ended_at), outcome=outcome, aborted=bool(aborted), attempt=int(attempt),
        is_reference=bool(is_reference), axis=axis, runs_of_unit=runs_of_unit,
        part_number=part_number,
    )


def _with_count(summary: RunSummary, count: int) -> RunSummary:
    from dataclasses import replace

    return replace(summary, runs_of_unit=count)
