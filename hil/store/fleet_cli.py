"""``gimbal-hil results spc / export / yield / report``: the fleet statistics of
:mod:`hil.fleet` over the stored runs.

``spc PARAM`` exits 1 when a selected Nelson rule or the EWMA fires on one of the newest
``--gate-last`` runs (default 1: the unit just calibrated), so a line can gate on it; the
limits are the frozen baseline's when one was frozen (``spc baseline freeze PARAM``), else
trial limits from the runs shown.

A result is charted for one kind of unit (unit type and axis, and the part number of the
gimbal it is an axis of): when it is stored for several, ``--axis``, ``--part-number`` or
``--unit-type`` chooses one and without them the command is refused naming them, each with
the options that pick it; the report shows one section per kind. Baselines are frozen per
kind. ``--part-number`` (with ``--revision``) keeps every command, ``yield`` too, to the
gimbals of that part number; ``yield`` shows the first-pass yield of the units, of the
gimbals (a gimbal passes first time when its first gimbal certificate is PASS) and of each
kind of axis.
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
    from hil.store.query import Kind, StoredGimbal, StoredResult

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
    add_kind_arguments(spc)
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
    add_kind_arguments(export)
    export.add_argument("--format", choices=EXPORT_FORMATS, default="csv", metavar="FORMAT",
                        help=" or ".join(EXPORT_FORMATS))
    export.add_argument("--output", type=Path, required=True, help="file to write")
    fpy = add("yield", "first-pass yield per station and/or day: units, gimbals, axes")
    add_part_arguments(fpy)
    fpy.add_argument("--by", choices=YIELD_GROUPS, default="station", metavar="GROUP",
                     help="group the runs by " + ", ".join(YIELD_GROUPS))
    report = add("report", "HTML fleet report: histograms, charts, Cpk, yield")
    report.add_argument("--html", type=Path, required=True, help="file to write")
    add_kind_arguments(report)
    report.add_argument("--parameters", default=None,
                        help="comma list of results (default: every stored result)")


def add_kind_arguments(parser: argparse.ArgumentParser) -> None:
    """``--axis``, ``--unit-type``, ``--part-number`` and ``--revision``: which kind of unit
    a result's series is of."""
    parser.add_argument("--axis", default=None,
                        help="only units of this axis, e.g. elevation; needed when a result "
                             "is stored for several axes, which are never pooled (default: "
                             "the one axis the result is stored for)")
    parser.add_argument("--unit-type", default=None,
                        help="only units of this type, the profile's unit type (default: "
                             "the one type the result is stored for)")
    add_part_arguments(parser)


def add_part_arguments(parser: argparse.ArgumentParser) -> None:
    """``--part-number`` and ``--revision``: only the gimbals of one part number."""
    parser.add_argument("--part-number", default=None, metavar="PN",
                        help="only the axes of gimbals of this part number, from their "
                             "stored gimbal certificates; 'none': only units without one "
                             "(default: every unit)")
    parser.add_argument("--revision", default=None, metavar="REV",
                        help="only gimbals of this revision of --part-number (default: "
                             "every revision)")


def part_selection(args: argparse.Namespace) -> tuple[str | None, str | None]:
    """``--part-number`` and ``--revision``.

    Raises
    ------
    InputError
        ``--revision`` without ``--part-number``.
    """
    part_number, revision = getattr(args, "part_number", None), getattr(args, "revision", None)
    if revision is not None and part_number is None:
        raise InputError(f"--revision {revision} is a revision of a part number: give "
                         "--part-number too")
    return part_number, revision


# the options that pick a kind, fewest first: the first set whose values tell every kind
# found apart is named with each (a unit without a gimbal certificate: --part-number none)
_PICKERS: tuple[tuple[str, ...], ...] = (
    ("axis",), ("part_number",), ("part_number", "axis"), ("unit_type",),
    ("unit_type", "axis"), ("part_number", "unit_type", "axis"))


def _picking(kinds: list[Kind]) -> tuple[str, ...]:
    for fields in _PICKERS:
        if len({tuple(getattr(k, f) for f in fields) for k in kinds}) == len(kinds):
            return fields
    return _PICKERS[-1]


def _options(kind: Kind, fields: tuple[str, ...]) -> str:
    def shown(value: str) -> str:
        return value if value.replace("-", "").replace("_", "").isalnum() else f"'{value}'"

    from hil.store.query import NO_PART_NUMBER

    return " ".join(f"--{field.replace('_', '-')} {shown(getattr(kind, field) or NO_PART_NUMBER)}"
                    for field in fields)


def one_kind(store: Store, name: str, args: argparse.Namespace,
             since: datetime | None) -> Kind:
    """The one kind of unit (unit type, axis) ``name``'s series is of, after ``--axis`` and
    ``--unit-type``.

    Raises
    ------
    InputError
        No run matches, or several kinds do (listed with the option that picks each).
    """
    from hil.store.query import result_kinds

    part_number, revision = part_selection(args)
    kinds = result_kinds(store, name, station=args.station, since=since, axis=args.axis,
                         unit_type=args.unit_type, part_number=part_number,
                         revision=revision)
    if not kinds:
        given = " ".join(f"{flag} {value}" for flag, value in (
            ("--axis", args.axis), ("--unit-type", args.unit_type),
            ("--part-number", part_number), ("--revision", revision)) if value is not None)
        narrowed = f" with {given}" if given else ""
        raise InputError(f"no stored results named '{name}'{narrowed} in {store.url}")
    if len(kinds) > 1:
        fields = _picking(sorted(kinds))
        listed = "; ".join(f"{kind}: {count} run(s), {_options(kind, fields)}"
                           for kind, count in sorted(kinds.items()))
        raise InputError(f"'{name}' is stored for {len(kinds)} kinds of unit, which are never "
                         f"pooled ({listed}): choose one")
    return next(iter(kinds))


def baseline_key(name: str, kind: Kind, revision: str | None = None) -> str:
    """Where the frozen baseline of ``name`` for ``kind`` (of ``revision`` of its part
    number, when one was chosen) is kept: ``spc:UNIT_TYPE/AXIS:NAME`` for a unit without a
    gimbal certificate, ``spc:PN[ rev REV]/UNIT_TYPE/AXIS:NAME`` for a gimbal's axis."""
    if not kind.part_number:
        return f"{BASELINE_PREFIX}{kind.unit_type}/{kind.axis}:{name}"
    part = kind.part_number + (f" rev {revision}" if revision is not None else "")
    return f"{BASELINE_PREFIX}{part}/{kind.unit_type}/{kind.axis}:{name}"


def load_kind_baseline(store: Store, name: str, kind: Kind,
                       revision: str | None = None) -> dict[str, Any] | None:
    """The frozen baseline of ``name`` for ``kind``; one frozen before baselines were kept
    per part number (``spc:UNIT_TYPE/AXIS:NAME``) is used for a part number's axis while
    its unit type and axis are stored for that part number only, and one frozen before
    baselines were kept per kind (``spc:NAME``) while the store holds that result for one
    kind only."""
    from hil.store.query import Kind, load_baseline, result_kinds

    found = load_baseline(store, baseline_key(name, kind, revision))
    if found is None and kind.part_number and revision is None and list(result_kinds(
            store, name, axis=kind.axis, unit_type=kind.unit_type)) == [kind]:
        found = load_baseline(store, baseline_key(name, Kind(kind.unit_type, kind.axis)))
    if found is None and revision is None and len(result_kinds(store, name)) == 1:
        found = load_baseline(store, BASELINE_PREFIX + name)
    return found


def run(args: argparse.Namespace, store: Store) -> int:
    """Run one of this module's subcommands; its exit code."""
    from hil.fleet.commands import export_rows, fleet_report_html
    from hil.store.query import result_kinds, result_series, run_summaries

    since = _since(args.since)
    command = args.results_command
    part_number, revision = part_selection(args)
    if command == "spc":
        return _spc(args, store, since)
    if command == "export":
        kind = one_kind(store, args.parameter, args, since)
        points = result_series(store, args.parameter, station=args.station, since=since,
                               include_reference=True, kind=kind, revision=revision)
        _require(points, args.parameter, store)
        path = _writing(args.output, lambda: export_rows(points, format=args.format,
                                                         path=args.output))
        print(f"{len(points)} run(s) of {args.parameter} written to {path}")
        return 0
    if command == "yield":
        return _yield(args, store, since)
    names = (args.parameters.split(",") if args.parameters else _stored_names(store))
    # one section per result and kind of unit: "inertia_kg_m2 (GMB-2 azimuth axis)" when the
    # result is stored for several kinds
    series: dict[str, list[StoredResult]] = {}
    baselines: dict[str, dict[str, Any]] = {}
    for name in names:
        kinds = sorted(result_kinds(store, name, station=args.station, since=since,
                                    axis=args.axis, unit_type=args.unit_type,
                                    part_number=part_number, revision=revision))
        if not kinds:
            series[name] = []  # asked for, none stored: the report says so
        for kind in kinds:
            label = name if len(kinds) == 1 else f"{name} ({kind})"
            series[label] = result_series(store, name, station=args.station, since=since,
                                          kind=kind, revision=revision)
            if (found := load_kind_baseline(store, name, kind, revision)) is not None:
                baselines[label] = found
    summaries = run_summaries(store, station=args.station, since=since,
                              part_number=part_number, revision=revision)
    path = _writing(args.html, lambda: fleet_report_html(series, summaries, args.html,
                                                         baselines=baselines))
    print(f"fleet report of {len(names)} result(s) written to {path}")
    return 0


def _spc(args: argparse.Namespace, store: Store, since: datetime | None) -> int:
    from hil.fleet.baseline import freeze_baseline
    from hil.fleet.charts import EwmaSettings
    from hil.fleet.commands import has_signal, spc_report
    from hil.store.query import result_series, save_baseline

    words: list[str] = args.words
    _, revision = part_selection(args)
    if words[:2] == ["baseline", "freeze"] and len(words) == 3:
        name = words[2]
        kind = one_kind(store, name, args, since)
        points = result_series(store, name, station=args.station, since=since, kind=kind,
                               revision=revision)
        frozen = freeze_baseline(points, parameter=name, frozen_at=datetime.now(UTC))
        save_baseline(store, baseline_key(name, kind, revision), frozen.to_dict())
        print(json.dumps(frozen.to_dict(), indent=2) if args.json else
              f"baseline for {name} ({kind}) frozen from {frozen.n} runs "
              f"({frozen.first_started_at} … {frozen.last_started_at}) in {store.url}")
        return 0
    if len(words) != 1:
        raise InputError("spc takes one result name, or: spc baseline freeze PARAM")
    name = words[0]
    kind = one_kind(store, name, args, since)
    points = result_series(store, name, station=args.station, since=since, kind=kind,
                           revision=revision)
    _require(points, name, store)
    baseline = load_kind_baseline(store, name, kind, revision)
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


def _yield(args: argparse.Namespace, store: Store, since: datetime | None) -> int:
    """First-pass yield of the units, the gimbals (their first gimbal certificates, per
    part number) and each kind of axis, grouped by ``--by``."""
    from hil.fleet.commands import yield_table
    from hil.store.query import gimbal_certificates, run_summaries

    part_number, revision = part_selection(args)
    runs = run_summaries(store, station=args.station, since=since, part_number=part_number,
                         revision=revision)
    # a gimbal's first certificate is its first, whatever --station and --since keep
    every = gimbal_certificates(store, part_number=part_number, revision=revision)
    firsts: dict[str, StoredGimbal] = {}
    for certificate in every:
        firsts.setdefault(certificate.serial, certificate)
    reference = {r.serial for r in runs if r.is_reference}  # golden units left out
    kept = [g for g in firsts.values() if g.serial not in reference
            and (args.station is None or g.station == args.station)
            and (since is None or g.issued_at >= since)]
    result = yield_table(runs, by=args.by, gimbals=kept)
    print(json.dumps(result.to_json(), indent=2) if args.json else result.table())
    return 0


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
