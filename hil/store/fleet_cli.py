"""``gimbal-hil results spc / export / yield / report``: the fleet statistics of
:mod:`hil.fleet` over the stored runs.

``spc PARAM`` exits 1 when a selected Nelson rule or the EWMA fires on one of the newest
``--gate-last`` runs (default 1: the unit just calibrated), so a line can gate on it; the
limits are the frozen baseline's when one was frozen (``spc baseline freeze PARAM``), else
trial limits from the runs shown.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hil.errors import InputError

if TYPE_CHECKING:  # loaded when a command runs: `gimbal-hil --help` stays fast
    from argparse import _FormatterClass  # typeshed's only

    from hil.store.engine import Store

BASELINE_PREFIX = "spc:"
EXPORT_FORMATS = ("csv", "parquet")
YIELD_GROUPS = ("station", "day", "station_day")


def add_arguments(commands: argparse._SubParsersAction[argparse.ArgumentParser],
                  common: argparse.ArgumentParser, *,
                  formatter_class: _FormatterClass = argparse.HelpFormatter) -> None:
    """Add ``spc``, ``export``, ``yield`` and ``report`` to the ``results`` subcommands
    (their help formatted by ``formatter_class``)."""
    selection = argparse.ArgumentParser(add_help=False)
    selection.add_argument("--station", default=None,
                           help="only this station id (default: every station)")
    selection.add_argument("--since", default=None,
                           help="only runs from this date, YYYY-MM-DD (default: every run)")

    def add(name: str, text: str, description: str | None = None) -> argparse.ArgumentParser:
        return commands.add_parser(name, parents=[common, selection], help=text,
                                   description=description or text,
                                   formatter_class=formatter_class)

    spc = add("spc", "one result's capability, I-MR chart, Nelson rules, EWMA",
              "capability, I-MR chart, Nelson rules, EWMA of one result (exit 1 on a "
              "signal); 'spc baseline freeze PARAM' freezes the limits")
    spc.add_argument("words", nargs="+", metavar="PARAM",
                     help="the result's name, or: baseline freeze PARAM")
    spc.add_argument("--rules", default="1,2,5,6", help="Nelson rules (comma list or 'all')")
    spc.add_argument("--ewma-lambda", type=float, default=0.2,
                     help="the EWMA's weight of the newest run")
    spc.add_argument("--ewma-l", type=float, default=3.0,
                     help="the EWMA's limits, in its standard deviations")
    spc.add_argument("--gate-last", type=int, default=1,
                     help="exit 1 on a signal among the newest N runs (0: any run)")
    export = add("export", "one result's stored values as CSV or parquet")
    export.add_argument("parameter", metavar="PARAM", help="the result's name")
    export.add_argument("--format", choices=EXPORT_FORMATS, default="csv", metavar="FORMAT",
                        help=" or ".join(EXPORT_FORMATS))
    export.add_argument("--output", type=Path, required=True, help="file to write")
    fpy = add("yield", "first-pass yield per station and/or day")
    fpy.add_argument("--by", choices=YIELD_GROUPS, default="station", metavar="GROUP",
                     help="group the runs by " + ", ".join(YIELD_GROUPS))
    report = add("report", "HTML fleet report: histograms, charts, Cpk, yield")
    report.add_argument("--html", type=Path, required=True, help="file to write")
    report.add_argument("--parameters", default=None,
                        help="comma list of results (default: every stored result)")


def run(args: argparse.Namespace, store: Store) -> int:
    """Run one of this module's subcommands; its exit code."""
    from hil.fleet.commands import export_rows, fleet_report_html, yield_table
    from hil.store.query import load_baseline, result_series, run_summaries

    since = _since(args.since)
    command = args.results_command
    if command == "spc":
        return _spc(args, store, since)
    if command == "export":
        points = result_series(store, args.parameter, station=args.station, since=since,
                               include_reference=True)
        _require(points, args.parameter, store)
        path = _writing(args.output, lambda: export_rows(points, format=args.format,
                                                         path=args.output))
        print(f"{len(points)} run(s) of {args.parameter} written to {path}")
        return 0
    if command == "yield":
        result = yield_table(run_summaries(store, station=args.station, since=since),
                             by=args.by)
        print(json.dumps(result.to_json(), indent=2) if args.json else result.table())
        return 0
    names = (args.parameters.split(",") if args.parameters else _stored_names(store))
    series = {name: result_series(store, name, station=args.station, since=since)
              for name in names}
    baselines = {name: found for name in names
                 if (found := load_baseline(store, BASELINE_PREFIX + name)) is not None}
    summaries = run_summaries(store, station=args.station, since=since)
    path = _writing(args.html, lambda: fleet_report_html(series, summaries, args.html,
                                                         baselines=baselines))
    print(f"fleet report of {len(names)} result(s) written to {path}")
    return 0


def _spc(args: argparse.Namespace, store: Store, since: datetime | None) -> int:
    from hil.fleet.baseline import freeze_baseline
    from hil.fleet.charts import EwmaSettings
    from hil.fleet.commands import has_signal, spc_report
    from hil.store.query import load_baseline, result_series, save_baseline

    words: list[str] = args.words
    if words[:2] == ["baseline", "freeze"] and len(words) == 3:
        name = words[2]
        points = result_series(store, name, station=args.station, since=since)
        frozen = freeze_baseline(points, parameter=name, frozen_at=datetime.now(UTC))
        save_baseline(store, BASELINE_PREFIX + name, frozen.to_dict())
        print(json.dumps(frozen.to_dict(), indent=2) if args.json else
              f"baseline for {name} frozen from {frozen.n} runs "
              f"({frozen.first_started_at} … {frozen.last_started_at}) in {store.url}")
        return 0
    if len(words) != 1:
        raise InputError("spc takes one result name, or: spc baseline freeze PARAM")
    name = words[0]
    points = result_series(store, name, station=args.station, since=since)
    _require(points, name, store)
    baseline = load_baseline(store, BASELINE_PREFIX + name)
    rules: Any = "all" if args.rules == "all" else [int(r) for r in args.rules.split(",") if r]
    result = spc_report(points, parameter=name, rules=rules,
                        limits_from="data" if baseline is None else "baseline",
                        baseline=baseline,
                        ewma=EwmaSettings(lam=args.ewma_lambda, width=args.ewma_l))
    signal = has_signal(result, last=args.gate_last or None)
    print(json.dumps({**result.to_json(), "signal": signal}, indent=2) if args.json
          else result.table())
    if signal and not args.json:
        scope = ("the newest run" if args.gate_last == 1 else
                 "any run" if not args.gate_last else f"the newest {args.gate_last} runs")
        print(f"SIGNAL: a selected rule or the EWMA fired on {scope} (exit 1)")
    return 1 if signal else 0


def _writing(path: Path, write: Callable[[], Path]) -> Path:
    """``write()``; a file that cannot be written is one line naming it (exit 2).

    Raises
    ------
    InputError
        The folder is missing or read-only, the path is a folder, the disk is full, …
    """
    try:
        return write()
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror or exc}", source=str(path)) from None


def _since(text: str | None) -> datetime | None:
    if text is None:
        return None
    try:
        return datetime.fromisoformat(text).replace(tzinfo=UTC)
    except ValueError:
        raise InputError(f"not a date (YYYY-MM-DD): {text!r}", source="--since") from None


def _require(points: list[Any], name: str, store: Store) -> None:
    if not points:
        raise InputError(f"no stored results named '{name}' in {store.url}")


def _stored_names(store: Store) -> list[str]:
    from sqlalchemy import select

    from hil.store.schema import results

    with store.engine.connect() as connection:
        return sorted(connection.execute(select(results.c.name).distinct()).scalars())
