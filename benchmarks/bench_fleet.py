"""Benchmark (not a timed test): the fleet statistics on a large series, and the false-alarm
rates of the ``spc`` gate on in-control data.

    python -m benchmarks.bench_fleet [--runs 100000] [--series 4000] [--seed 5]

Speed: ``spc_report`` (all eight rules, EWMA), its JSON, the trend table and both exports on
``--runs`` results of one parameter (plain dataclasses, as the store hands them over).
Gate: over ``--series`` in-control normal series of 50 runs, how often ``has_signal`` is
true with trial limits, with known μ and σ, and for the newest run alone (``last=1``).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from datetime import timedelta
from pathlib import Path

import numpy as np

from hil.fleet.baseline import Baseline
from hil.fleet.commands import export_rows, has_signal, spc_report, trend_table
from tests.fleet.points import drifting_values, series


def _timed(label: str, work: object) -> None:
    start = time.perf_counter()
    work()  # type: ignore[operator]
    print(f"{label:<40}{time.perf_counter() - start:8.2f} s")


def speed(runs: int) -> None:
    points = series(drifting_values(runs, drift_from=10**9), step=timedelta(minutes=1))
    result = spc_report(points, parameter="p", rules="all")
    _timed(f"spc_report, all rules, {runs} runs", lambda: spc_report(points, parameter="p",
                                                                     rules="all"))
    _timed("its JSON", result.to_json)
    _timed("trend table", lambda: trend_table(points).table())
    with tempfile.TemporaryDirectory() as folder:
        _timed("export csv", lambda: export_rows(points, format="csv",
                                                 path=Path(folder) / "r.csv"))
        _timed("export parquet", lambda: export_rows(points, format="parquet",
                                                     path=Path(folder) / "r.parquet"))


def gate(count: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    known = Baseline(parameter="p", unit="kg·m²", n=25, centre=3.6e-3, mr_bar=1.128 * 3e-5,
                     first_started_at="", last_started_at="", frozen_at="", run_ids=())
    trial = known_any = newest = every_rule = 0
    for _ in range(count):
        points = series(3.6e-3 + 3e-5 * rng.standard_normal(50))
        trial += has_signal(spc_report(points, parameter="p"))
        every_rule += has_signal(spc_report(points, parameter="p", rules="all"))
        against = spc_report(points, parameter="p", limits_from="baseline", baseline=known)
        known_any += has_signal(against)
        newest += has_signal(against, last=1)
    print(f"in control, 50 runs, {count} series: gate opens on {trial / count:.1%} "
          f"(trial limits; all eight rules {every_rule / count:.1%}), {known_any / count:.1%} "
          f"(known μ, σ); newest run alone {newest / count:.2%}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=100_000)
    parser.add_argument("--series", type=int, default=4000)
    parser.add_argument("--seed", type=int, default=5)
    args = parser.parse_args()
    speed(args.runs)
    gate(args.series, args.seed)


if __name__ == "__main__":
    main()
