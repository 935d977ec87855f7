"""One ``gimbal-hil characterise`` run: check the options against the folder's population,
draw, calibrate with progress, summarise, write the map or its validation."""

from __future__ import annotations

import argparse
import json
import threading
import time
import tomllib
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

import tomli_w

from hil.characterise.bins import binned, miss_table
from hil.characterise.draw import PROFILES, Unit, write_population
from hil.characterise.method_map import HEADER, bias_map, earlier_results, with_validation
from hil.characterise.run import run_population
from hil.characterise.summary import by_variant, summarise, table, variant_table
from hil.errors import InputError
from hil.profile import resolve_profile_path

STATE = "population.toml"  # the options a folder's population was drawn with


def characterise(args: argparse.Namespace) -> int:
    """Run ``gimbal-hil characterise`` (see :mod:`hil.characterise.cli`).

    Raises
    ------
    InputError
        Fewer than one unit or job; ``--out`` holds a population drawn with other options;
        a profile or a map to validate that cannot be read.
    """
    if args.units < 1:
        raise InputError(f"must be at least 1, got {args.units}", source="--units")
    if args.jobs < 1:
        raise InputError(f"must be at least 1, got {args.jobs}", source="--jobs")
    profiles = [str(resolve_profile_path(p)) for p in args.profile or PROFILES]
    if args.validate_map is not None and not args.validate_map.is_file():
        raise InputError("map file not found", source=str(args.validate_map))
    state = {"profiles": profiles, "units_per_profile": args.units, "seed": args.seed,
             "method_bias": args.method_bias or "shipped"}
    _claim(args.out, state)
    started = time.perf_counter()
    units = write_population(args.out / "units", units_per_profile=args.units,
                             seed=args.seed, profiles=profiles)
    rows = run_population(units, args.out / "certificates", workers=args.jobs,
                          scheduler=args.scheduler, method_bias=args.method_bias,
                          reuse=True, progress=_progress(len(units), started))
    summaries = summarise(rows)
    where = (f"on the cluster at {args.scheduler}" if args.scheduler is not None
             else f"with {args.jobs} job(s)")
    print(f"\n{len(units)} units, {len(rows)} results with a truth, "
          f"{time.perf_counter() - started:.0f} s {where}\n")
    print("\n".join(table(summaries)))
    bins = binned(rows)
    print("\n" + "\n".join(miss_table(bins)))
    per_variant = by_variant(rows)
    if per_variant:
        print("\nBy the simulator's drawn variant:\n" + "\n".join(variant_table(per_variant)))
    population = (f"gimbal-hil characterise --units {args.units} --seed {args.seed} "
                  f"--method-bias {state['method_bias']}: {len(units)} units")
    if args.write_map is not None:
        _write(args.write_map, bias_map(rows, population=population,
                                        earlier=earlier_results(units)))
        print(f"method-bias map: {args.write_map}")
    if args.validate_map is not None:
        document = tomllib.loads(args.validate_map.read_text(encoding="utf-8"))
        _write(args.validate_map, with_validation(document, summaries, per_variant))
        print(f"validation added to {args.validate_map}")
    (args.out / "summary.json").write_text(json.dumps(
        {"population": [asdict(s) for s in summaries], "rows": [asdict(r) for r in rows],
         "by_covariate": [asdict(b) for b in bins],
         "by_variant": {v: [asdict(s) for s in group] for v, group in per_variant.items()}},
        indent=1), encoding="utf-8")
    return 0


def _claim(folder: Path, state: dict[str, Any]) -> None:
    """Record the population's options in ``folder``, or check them against a run before
    (the units drawn and the certificates kept depend on them)."""
    path = folder / STATE
    if path.is_file():
        before = tomllib.loads(path.read_text(encoding="utf-8"))
        changed = [f"{key} {before.get(key)!r} → {value!r}" for key, value in state.items()
                   if before.get(key) != value]
        if changed:
            raise InputError(f"holds a population drawn with other options ({'; '.join(changed)}"
                             "): use another folder, or the same options to resume it",
                             source=str(folder))
        return
    folder.mkdir(parents=True, exist_ok=True)
    path.write_text(tomli_w.dumps(state), encoding="utf-8")


def _progress(total: int, started: float) -> Callable[[Unit, int], None]:
    """A thread-safe progress line per finished unit."""
    lock, done = threading.Lock(), [0]

    def report(unit: Unit, results: int) -> None:
        with lock:
            done[0] += 1
            found = f"{results} results" if results else "no certificate: its calibration failed"
            print(f"[{done[0]}/{total}] {unit.serial}: {found} "
                  f"({time.perf_counter() - started:.0f} s)", flush=True)

    return report


def _write(path: Path, document: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(HEADER + tomli_w.dumps(document), encoding="utf-8")
