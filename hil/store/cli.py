"""``gimbal-hil results``: ingest, sync, units, history SERIAL, trend PARAM, and the fleet
statistics (spc, export, yield, report: :mod:`hil.store.fleet_cli`).

Each reading command prints a table a person reads (values as GUM asks: U to two
significant digits, the value to the same decimal) or, with ``--json``, full precision.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hil.errors import InputError
from hil.gum import rounded_pair
from hil.store import fleet_cli

if TYPE_CHECKING:  # the store's modules load when a command runs (SQLAlchemy is slow to)
    from hil.store.engine import Store
    from hil.store.ingest import Ingested
    from hil.store.query import RunSummary, StoredResult

TIME_FORMAT = "%Y-%m-%d %H:%M"
WRITING_COMMANDS = ("ingest", "sync")  # the only ones that may create a store


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``results`` subcommands to ``parser``."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--store", default=None,
                        help="store URL (postgresql://…, sqlite:///FILE; default: "
                        "$GIMBAL_HIL_STORE, the station file's store, else OUT/results.sqlite)")
    common.add_argument("--out", type=Path, default=Path("certificates"),
                        help="the calibrations' --out (embedded store and outbox)")
    common.add_argument("--station-file", type=Path, default=None,
                        help="station TOML whose [station] store to use (default: none)")
    common.add_argument("--json", action="store_true",
                        help="print JSON, full precision (default: a table)")
    # the sub-subcommands format their help as the parent does (defaults shown)
    commands = parser.add_subparsers(
        dest="results_command", required=True, title="commands", metavar="COMMAND",
        help="'gimbal-hil results COMMAND --help' shows a command's options")

    def add(name: str, text: str) -> argparse.ArgumentParser:
        return commands.add_parser(name, parents=[common], help=text, description=text,
                                   formatter_class=parser.formatter_class)

    ingest = add("ingest", "store certificates written before the store existed")
    ingest.add_argument("directories", type=Path, nargs="+", metavar="DIR",
                        help="a folder of serials or one serial's folder (history included)")
    add("sync", "upload the runs waiting in the outbox")
    add("units", "every unit: its last run and outcome")
    hist = add("history", "every run of one unit; as-found / as-left")
    hist.add_argument("serial", metavar="SERIAL", help="the unit's serial number")
    trend = add("trend", "one result over the runs")
    trend.add_argument("parameter", metavar="PARAM", help="the result's name")
    trend.add_argument("--station", default=None,
                       help="only this station id (default: every station)")
    trend.add_argument("--since", default=None,
                       help="only runs from this date, YYYY-MM-DD (default: every run)")
    trend.add_argument("--include-aborted", action="store_true",
                       help="also aborted runs (default: left out)")
    fleet_cli.add_kind_arguments(trend)
    trend.add_argument("--include-reference", action="store_true",
                       help="also reference (golden) units' runs (default: left out)")
    fleet_cli.add_arguments(commands, common, formatter_class=parser.formatter_class)


def run(args: argparse.Namespace) -> int:
    """Run one ``results`` subcommand; its exit code.

    A database error while it runs (a table gone, a lock held past the timeout, the server
    gone) is one line, exit 2 (:func:`hil.store.engine.store_failure`), never a traceback.
    """
    from sqlalchemy.exc import SQLAlchemyError

    from hil.drives.station import load_station_identity
    from hil.store.engine import open_store, resolve_store_url, store_failure, store_target
    from hil.store.outbox import foreign_entries, pending, refusal

    station_store = (load_station_identity(args.station_file).store
                     if args.station_file is not None else None)
    url = resolve_store_url(args.store, out_dir=args.out, station_store=station_store)
    command = args.results_command
    if command not in WRITING_COMMANDS:
        _require_existing_store(url)
    if command == "sync":  # every waiting run meant for another store: no store opened
        foreign = foreign_entries(args.out, store_target(url))
        if foreign and sum(map(len, foreign.values())) == len(pending(args.out)):
            raise InputError(refusal(args.out, foreign, _shown(url)))
    store = open_store(url)
    try:
        return _run(args, store)
    except SQLAlchemyError as exc:
        raise store_failure(exc, store.url, url=url) from None
    finally:
        store.close()


def _shown(url: str) -> str:
    from hil.store.engine import parse_store_url

    return parse_store_url(url).render_as_string(hide_password=True)


def _run(args: argparse.Namespace, store: Store) -> int:
    from hil.store.ingest import ingest_tree
    from hil.store.outbox import sync_outbox
    from hil.store.query import gimbal_identities, units

    command = args.results_command
    if command in WRITING_COMMANDS:
        done = (sync_outbox(store, args.out) if command == "sync" else
                [i for d in args.directories for i in ingest_tree(store, d)])
        _emit(args, _ingested_json(done, store), _ingested_text(done, store, command))
        return 0
    if command == "units":
        found, identities = units(store), gimbal_identities(store)
        _emit(args, [dict(_summary_json(s), **_identity_json(identities.get(s.serial)))
                     for s in found], _units_text(found, identities))
        return 0
    if command == "history":
        return _history(args, store)
    if command == "trend":
        return _trend(args, store)
    return fleet_cli.run(args, store)


def _require_existing_store(url: str) -> None:
    """A reading command never creates a store: an embedded (SQLite) store must exist.

    Raises
    ------
    InputError
        The SQLite file is not there (a PostgreSQL database cannot be told from here).
    """
    from hil.store.engine import parse_store_url

    parsed = parse_store_url(url)
    if parsed.get_backend_name() != "sqlite" or parsed.database in (None, "", ":memory:"):
        return
    path = Path(str(parsed.database))
    if not path.is_file():
        raise InputError(f"no results store in {path.parent} (no {path.name}; calibrate, "
                         "'results ingest' or 'results sync' create one)")


def _emit(args: argparse.Namespace, data: Any, text: str) -> None:
    print(json.dumps(data, indent=2) if args.json else text)


def _ingested_json(done: Sequence[Ingested], store: Store) -> dict[str, Any]:
    return {"store": store.url, "new": sum(i.new for i in done),
            "already_stored": sum(not i.new for i in done),
            "runs": [{"certificate_id": i.certificate_id, "run_id": i.run_id,
                      "serial": i.serial, "new": i.new} for i in done]}


def _ingested_text(done: Sequence[Ingested], store: Store, command: str) -> str:
    new = sum(i.new for i in done)
    lines = [f"{'+' if i.new else '='} {i.certificate_id}" for i in done]
    lines.append(f"{command}: {new} run(s) stored, {len(done) - new} already stored "
                 f"({store.url})")
    return "\n".join(lines)


def _summary_json(s: RunSummary) -> dict[str, Any]:
    return {"serial": s.serial, "unit_type": s.unit_type, "axis": s.axis, "run_id": s.run_id,
            "certificate_id": s.certificate_id, "station": s.station, "operator": s.operator,
            "started_at": s.started_at.isoformat(), "ended_at": s.ended_at.isoformat(),
            "outcome": s.outcome, "aborted": s.aborted, "attempt": s.attempt,
            "is_reference": s.is_reference, "runs": s.runs_of_unit}


def _identity_json(identity: tuple[str, str] | None) -> dict[str, str | None]:
    part, revision = identity or (None, None)
    return {"part_number": part, "revision": revision}


def _units_text(found: Sequence[RunSummary],
                identities: Mapping[str, tuple[str, str]]) -> str:
    # a gimbal (several axes under one serial) shows its axes, and its part number and
    # revision once its gimbal certificate is stored; its outcome is the worst of each
    # axis's latest run
    def kind(s: RunSummary) -> str:
        if s.serial in identities:
            part, revision = identities[s.serial]
            return f"{part}{f' rev {revision}' if revision else ''}: {s.axis}"
        return s.unit_type if "," not in s.axis else f"gimbal: {s.axis}"

    rows = [(s.serial, kind(s),
             str(s.runs_of_unit), s.started_at.strftime(TIME_FORMAT),
             s.station, s.outcome + (" (reference)" if s.is_reference else ""))
            for s in found]
    return _table(("serial", "type", "runs", "last run (UTC)", "station", "outcome"), rows,
                  empty="no runs stored")


def _history(args: argparse.Namespace, store: Store) -> int:
    from hil.store.query import gimbal_certificates, history, run_results

    runs = history(store, args.serial)
    if not runs:
        raise InputError(f"no runs of unit '{args.serial}' in {store.url}")
    certified = gimbal_certificates(store, serial=args.serial)
    # as found → as left per axis: a gimbal's axes share its serial, never each other's runs
    axes: dict[str, list[Any]] = {}
    for summary in runs:
        axes.setdefault(summary.axis, []).append(summary)
    compared = []
    for axis, of_axis in axes.items():
        found = run_results(store, of_axis[-2].run_id) if len(of_axis) > 1 else {}
        left = run_results(store, of_axis[-1].run_id)
        compared.append((axis, of_axis, found,
                         [_as_found_left(name, found.get(name), row)
                          for name, row in left.items()]))
    if args.json:
        per_axis = [{"axis": axis, "as_found_run": of_axis[-2].run_id if found else None,
                     "as_left_run": of_axis[-1].run_id, "results": changes}
                    for axis, of_axis, found, changes in compared]
        latest = next(a for a in per_axis if a["as_left_run"] == runs[-1].run_id)
        _emit(args, {"serial": args.serial, "runs": [_summary_json(s) for s in runs],
                     **{k: v for k, v in latest.items() if k != "axis"},  # the latest run's
                     "axes": per_axis,
                     "gimbal_certificates": [_gimbal_json(g) for g in certified]}, "")
        return 0
    several = len(axes) > 1
    rows = [(str(s.attempt), *((s.axis,) if several else ()), s.started_at.strftime(TIME_FORMAT),
             s.station, s.operator, s.outcome + (" aborted" if s.aborted else ""),
             s.certificate_id) for s in runs]
    header = ("#", *(("axis",) if several else ()), "started (UTC)", "station", "operator",
              "outcome", "certificate")
    identity = (f" ({certified[-1].part_number}"
                + (f" rev {certified[-1].revision}" if certified[-1].revision else "") + ")"
                if certified else "")
    text = [f"unit {args.serial}{identity}: {len(runs)} run(s)"
            + (f" of {len(axes)} axes ({', '.join(axes)})" if several else ""),
            _table(header, rows)]
    if certified:
        text += ["", "gimbal certificates:", _table(
            ("issued (UTC)", "outcome", "axes", "certificate"),
            [(g.issued_at.strftime(TIME_FORMAT), g.outcome, ", ".join(g.axes),
              g.certificate_id) for g in certified])]
    for axis, of_axis, found, changes in compared:
        # a gimbal's axes each show their latest results, as found "-" before a second run
        if found or several:
            since_run = (f"as found (run {of_axis[-2].attempt}) → " if found else
                         "no earlier run of this axis (as found -) → ")
            text += ["", f"{axis + ': ' if several else ''}{since_run}as left (run "
                     f"{of_axis[-1].attempt}, the latest):",
                     _table(("result", "as found", "as left", "unit", "outcome"),
                            [_change_row(c) for c in changes])]
    print("\n".join(text))
    return 0


def _gimbal_json(g: Any) -> dict[str, Any]:
    return {"certificate_id": g.certificate_id, "part_number": g.part_number,
            "revision": g.revision, "outcome": g.outcome, "issued_at": g.issued_at.isoformat(),
            "axes": list(g.axes), "axis_certificates": list(g.axis_certificates)}


def _as_found_left(name: str, found: dict[str, Any] | None,
                   left: dict[str, Any]) -> dict[str, Any]:
    keep = ("value", "standard_uncertainty", "expanded_uncertainty", "outcome")
    return {"name": name, "unit": left["unit"],
            "as_found": {k: found[k] for k in keep} if found else None,
            "as_left": {k: left[k] for k in keep}}


def _change_row(change: dict[str, Any]) -> tuple[str, ...]:
    def shown(side: dict[str, Any] | None) -> str:
        if side is None:
            return "-"
        value, u = rounded_pair(side["value"], side["expanded_uncertainty"])
        return f"{value} ± {u}"

    found, left = change["as_found"], change["as_left"]
    outcome = f"{found['outcome']} → {left['outcome']}" if found else left["outcome"]
    return (change["name"], shown(found), shown(left), change["unit"], outcome)


def _trend(args: argparse.Namespace, store: Store) -> int:
    from hil.store.query import result_kinds, result_series

    since = _date(args.since) if args.since else None
    _known_parameter(store, args.parameter)
    part_number, revision = fleet_cli.part_selection(args)
    matching = result_kinds(store, args.parameter, station=args.station, since=since,
                            axis=args.axis, unit_type=args.unit_type,
                            part_number=part_number, revision=revision)
    # several kinds of unit are refused (never pooled); none is an empty trend
    series = result_series(store, args.parameter, station=args.station, since=since,
                           include_aborted=args.include_aborted,
                           include_reference=args.include_reference,
                           kind=fleet_cli.one_kind(store, args.parameter, args, since),
                           revision=revision) if matching else []
    values = [p.value for p in series]
    import statistics  # here: 15 ms of every command's start otherwise

    summary = {"n": len(values), "mean": statistics.fmean(values) if values else None,
               "standard_deviation": statistics.stdev(values) if len(values) > 1 else None}
    if args.json:
        _emit(args, {"parameter": args.parameter, "station": args.station,
                     "since": since.isoformat() if since else None, **summary,
                     "points": [_point_json(p) for p in series]}, "")
        return 0
    rows = [(p.started_at.strftime(TIME_FORMAT), p.serial, p.station,
             " ± ".join(rounded_pair(p.value, p.expanded_uncertainty)), p.unit, p.outcome)
            for p in series]
    text = [f"{args.parameter}: {len(series)} run(s)"
            + (f", station {args.station}" if args.station else "")
            + (f", since {since:%Y-%m-%d}" if since else ""),
            _table(("started (UTC)", "serial", "station", "value ± U", "unit", "outcome"),
                   rows, empty="no runs match")]
    sd = summary["standard_deviation"]
    if sd is not None and math.isfinite(sd) and sd > 0:
        mean, spread = rounded_pair(float(summary["mean"] or 0.0), sd)
        text.append(f"mean {mean}, standard deviation {spread} {series[0].unit} "
                    f"(n = {len(values)})")
    print("\n".join(text))
    return 0


def _point_json(p: StoredResult) -> dict[str, Any]:
    return {"run_id": p.run_id, "certificate_id": p.certificate_id, "serial": p.serial,
            "station": p.station, "started_at": p.started_at.isoformat(), "value": p.value,
            "standard_uncertainty": p.standard_uncertainty,
            "expanded_uncertainty": p.expanded_uncertainty, "unit": p.unit,
            "nominal": p.nominal, "lower_limit": p.lower_limit, "upper_limit": p.upper_limit,
            "outcome": p.outcome, "is_reference": p.is_reference}


def _known_parameter(store: Store, name: str) -> None:
    from sqlalchemy import select

    from hil.store.schema import results

    with store.engine.connect() as connection:
        known = sorted(connection.execute(select(results.c.name).distinct()).scalars())
    if known and name not in known:
        raise InputError(f"no result '{name}' in {store.url} (known: {', '.join(known)})")


def _date(text: str) -> datetime:
    try:
        moment = datetime.fromisoformat(text)
    except ValueError:
        raise InputError(f"not a date (YYYY-MM-DD): {text!r}", source="--since") from None
    return moment.replace(tzinfo=UTC) if moment.tzinfo is None else moment


def _table(header: Sequence[str], rows: Sequence[Sequence[str]], *, empty: str = "") -> str:
    if not rows:
        return empty
    widths = [max(len(str(r[i])) for r in (header, *rows)) for i in range(len(header))]
    lines = ["  ".join(str(c).ljust(w) for c, w in zip(r, widths, strict=True)).rstrip()
             for r in (header, *rows)]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)
