"""Does every certificate's k = 2 interval cover the truth about 95 % of the time?

    python -m benchmarks.bench_coverage --units 100 --pairs 20 --out /tmp/coverage

Draws ``--units`` simulated units of each demo profile across the profile's tolerance
ranges (:mod:`hil.characterise`, as ``gimbal-hil characterise`` does: every plant parameter
varied, every effect on, random noise seeds), calibrates each through ``gimbal-hil
calibrate --drive sim`` and reports per result the bias, the RMS of the normalised error
``(x − truth)/u`` and the fraction of truths inside ``±U``. Goal: coverage 93–98 %, RMS
normalised error 0.7–1.3. Results without a truth of the plant's are checked by
repeatability over ``--pairs`` units calibrated twice (what this adds to ``gimbal-hil
characterise``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import tomllib
from dataclasses import asdict
from pathlib import Path

import numpy as np
import tomli_w

from hil.characterise.draw import write_population
from hil.characterise.method_map import HEADER, bias_map, with_validation
from hil.characterise.run import calibrate, run_population
from hil.characterise.summary import repeatability, summarise, table
from hil.characterise.truth import NO_TRUTH


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--units", type=int, default=100, help="units per demo profile")
    parser.add_argument("--pairs", type=int, default=20, help="units per profile run twice")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--out", type=Path, default=Path("coverage-run"))
    parser.add_argument("--method-bias", default=None,
                        help="map the calibrations use ('off': none; default: shipped)")
    parser.add_argument("--reuse", action="store_true",
                        help="read the certificates already under --out instead of calibrating")
    parser.add_argument("--write-bias-map", type=Path, default=None,
                        help="write the map these results show (run with --method-bias off)")
    parser.add_argument("--write-validation", type=Path, default=None,
                        help="add each result's coverage here to the map the calibrations "
                             "used (a population not used to build it)")
    args = parser.parse_args()

    started = time.perf_counter()
    units = write_population(args.out / "units", units_per_profile=args.units, seed=args.seed)
    rows = run_population(units, args.out / "certificates", workers=args.workers,
                          method_bias=args.method_bias, reuse=args.reuse)
    summaries = summarise(rows)
    print(f"{len(units)} units, {len(rows)} results, {time.perf_counter() - started:.0f} s\n")
    if args.write_bias_map:
        population = (f"bench_coverage.py --units {args.units} --seed {args.seed} "
                      f"--method-bias {args.method_bias}: {len(units)} units")
        args.write_bias_map.write_text(
            HEADER + tomli_w.dumps(bias_map(rows, population=population)),
            encoding="utf-8")
    if args.write_validation:
        document = tomllib.loads(args.write_validation.read_text(encoding="utf-8"))
        args.write_validation.write_text(
            HEADER + tomli_w.dumps(with_validation(document, summaries)),
            encoding="utf-8")
    print("\n".join(table(summaries)))

    pairs = [u for u in units if int(u.serial.split("-")[1]) < args.pairs]
    z: dict[str, list[float]] = {}
    for unit in pairs:
        first = calibrate(unit, args.out / "certificates", method_bias=args.method_bias,
                          reuse=True)
        second = calibrate(unit, args.out / "pairs", seed=unit.seed + 1,
                           method_bias=args.method_bias, reuse=args.reuse)
        for name, value in repeatability(first, second).items():
            z.setdefault(name, []).append(value)
    print("\n| result (repeatability, two seeds) | pairs | RMS (x₁−x₂)/√(u₁²+u₂²) |")
    print("|---|---|---|")
    for name in sorted(z):
        mark = " (no truth)" if name in NO_TRUTH else ""
        print(f"| {name}{mark} | {len(z[name])} | {np.sqrt(np.mean(np.square(z[name]))):.2f} |")
    (args.out / "summary.json").write_text(json.dumps(
        {"population": [asdict(s) for s in summaries],
         "repeatability": {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in z.items()},
         "rows": [asdict(r) for r in rows]}, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
