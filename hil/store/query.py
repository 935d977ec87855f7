"""Read the store: the series statistics are computed on, the fleet's units, one unit's
history, and the frozen SPC baselines.

``result_series`` and :class:`StoredResult` are the interface the fleet statistics
(``hil.fleet``) are written against: keep their names and fields.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import delete, func, insert, select

from hil.store.engine import Store
from hil.store.schema import results, runs, spc_baselines


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
    runs_of_unit: int = 1


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
    if station is not None:
        query = query.where(runs.c.station == station)
    if since is not None:
        query = query.where(runs.c.started_at >= utc(since))
    if not include_aborted:
        query = query.where(runs.c.aborted.is_(False))
    if not include_reference:
        query = query.where(runs.c.is_reference.is_(False))
    with store.engine.connect() as connection:
        rows = connection.execute(query).all()
    return [
        StoredResult(
            run_id=r.run_id, certificate_id=r.certificate_id, serial=r.serial,
            station=r.station, started_at=utc(r.started_at), value=r.value,
            standard_uncertainty=r.standard_uncertainty,
            expanded_uncertainty=r.expanded_uncertainty, unit=r.unit, nominal=r.nominal,
            lower_limit=r.lower_limit, upper_limit=r.upper_limit, outcome=r.outcome,
            is_reference=bool(r.is_reference),
        )
        for r in rows
    ]


def units(store: Store) -> list[RunSummary]:
    """Every unit's latest run (with how many runs it has), by serial."""
    ranked = select(
        *_summary_columns(),
        func.row_number()
        .over(partition_by=runs.c.serial, order_by=(runs.c.started_at.desc(),
                                                    runs.c.run_id.desc()))
        .label("rank"),
        func.count().over(partition_by=runs.c.serial).label("runs_of_unit"),
    ).subquery()
    query = select(ranked).where(ranked.c.rank == 1).order_by(ranked.c.serial)
    with store.engine.connect() as connection:
        return [_summary(row._mapping) for row in connection.execute(query)]


def history(store: Store, serial: str) -> list[RunSummary]:
    """Every run of one unit, oldest first."""
    query = (
        select(*_summary_columns())
        .where(runs.c.serial == serial)
        .order_by(runs.c.started_at, runs.c.run_id)
    )
    with store.engine.connect() as connection:
        found = [_summary(row._mapping) for row in connection.execute(query)]
    return [_with_count(s, len(found)) for s in found]


def run_summaries(
    store: Store, *, station: str | None = None, since: datetime | None = None
) -> list[RunSummary]:
    """Every stored run (aborted and reference runs included: each carries its flags),
    oldest first; for yields per station and day.

    Parameters
    ----------
    store : Store
        An open store.
    station : str, optional
        Only runs of this station id.
    since : datetime, optional
        Only runs started at or after it (naive times are taken as UTC).
    """
    query = select(*_summary_columns()).order_by(runs.c.started_at, runs.c.run_id)
    if station is not None:
        query = query.where(runs.c.station == station)
    if since is not None:
        query = query.where(runs.c.started_at >= utc(since))
    with store.engine.connect() as connection:
        return [_summary(row._mapping) for row in connection.execute(query)]


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


def _summary_columns() -> tuple[Any, ...]:
    return (
        runs.c.run_id, runs.c.certificate_id, runs.c.serial, runs.c.unit_type,
        runs.c.station, runs.c.operator, runs.c.started_at, runs.c.ended_at, runs.c.outcome,
        runs.c.aborted, runs.c.attempt, runs.c.is_reference,
    )


def _summary(row: Any) -> RunSummary:
    return RunSummary(
        run_id=row["run_id"], certificate_id=row["certificate_id"], serial=row["serial"],
        unit_type=row["unit_type"], station=row["station"], operator=row["operator"],
        started_at=utc(row["started_at"]), ended_at=utc(row["ended_at"]),
        outcome=row["outcome"], aborted=bool(row["aborted"]), attempt=int(row["attempt"]),
        is_reference=bool(row["is_reference"]),
        runs_of_unit=int(row.get("runs_of_unit", 1) or 1),
    )


def _with_count(summary: RunSummary, count: int) -> RunSummary:
    from dataclasses import replace

    return replace(summary, runs_of_unit=count)
