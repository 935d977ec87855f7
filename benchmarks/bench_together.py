"""The gimbal's axes at the same time (``calibrate --gimbal --together``) against one after
the other: the cycle time, and whether any result moved.

    python -m benchmarks.bench_together --seeds 1 2 3 4 5 6 7 8 [--gimbal PROFILE]

Each seed calibrates the gimbal (default: the demo) on the simulator both ways (``--store off --
--no-documents``). Per result, the difference together − one after the other over the
seeds: its mean and that mean's standard error against the result's median expanded
uncertainty U. The two ways share the azimuth's noise streams, not the elevation's (its
own plant is seeded as the held partner's when shared), so the differences also hold the
noise; a result moved by running beside the other axis shows a mean difference beyond its
standard error, and a large one against U. This is the evidence a gimbal profile's
``[together] beside`` pair needs (:mod:`hil.gimbal.profile`): declare it, run this, keep it
only if no result moves.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

GIMBAL = "demo_gimbal"


def calibrate(out: Path, seed: int, together: bool, gimbal: str = GIMBAL) -> dict[str, Any]:
    """One calibration of the gimbal; its gimbal certificate."""
    argv = [sys.executable, "-m", "hil.cli", "calibrate", "--gimbal", gimbal, "--drive", "sim",
            "--unit-serial", f"BENCH-{seed:04d}", "--out", str(out), "--seed", str(seed),
            "--store", "off", *(["--together"] if together else []), "--", "--no-documents"]
    subprocess.run(argv, check=True, capture_output=True, text=True)
    path = out / f"BENCH-{seed:04d}" / "gimbal-certificate.json"
    issued: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return issued


def results(issued: dict[str, Any], folder: Path) -> dict[tuple[str, str], tuple[float, float]]:
    """(axis, result) → (value, U) of every axis section of a gimbal certificate."""
    found = {}
    for axis in issued["axes"]:
        for row in axis["results"]:
            if isinstance(row["value"], int | float) and row["expanded_uncertainty"]:
                found[axis["axis"], row["parameter"]] = (float(row["value"]),
                                                         float(row["expanded_uncertainty"]))
    return found


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5, 6, 7, 8])
    parser.add_argument("--gimbal", default=GIMBAL, help="gimbal profile (default: the demo)")
    args = parser.parse_args(argv)
    differences: dict[tuple[str, str], list[float]] = {}
    uncertainties: dict[tuple[str, str], list[float]] = {}
    cycles = []
    with tempfile.TemporaryDirectory(prefix="bench-together-") as scratch:
        for seed in args.seeds:
            ways = {}
            for together in (False, True):
                out = Path(scratch) / f"{seed}-{together}"
                issued = calibrate(out, seed, together, args.gimbal)
                ways[together] = results(issued, out)
                if together:
                    cycles.append(issued["cycle_time"])
            for key, (value, u) in ways[True].items():
                if key in ways[False]:
                    differences.setdefault(key, []).append(value - ways[False][key][0])
                    uncertainties.setdefault(key, []).append(u)
            print(f"seed {seed}: gimbal {cycles[-1]['together_s']:.1f} s, "
                  f"{cycles[-1]['ratio_to_slowest']:.3f} × the slowest axis", flush=True)
    last = cycles[-1]
    print(f"\nown motion {last['own_motion_s']}, one after the other "
          f"{last['one_after_the_other_s']:.1f} s, together {last['together_s']:.1f} s, "
          f"{last['ratio_to_slowest']:.3f} × the slowest axis; beside: {last['beside']}\n")
    print("| axis | result | seeds | mean difference / U | its standard error / U | "
          "max abs difference / U |")
    print("|---|---|---|---|---|---|")
    shifts = []
    for (axis, name), values in sorted(differences.items()):
        u = statistics.median(uncertainties[axis, name])
        mean = statistics.fmean(values) / u
        error = (statistics.stdev(values) / math.sqrt(len(values)) / u
                 if len(values) > 1 else math.nan)
        worst = max(abs(v) for v in values) / u
        shifts.append((abs(mean), axis, name))
        print(f"| {axis} | {name} | {len(values)} | {mean:+.3f} | {error:.3f} | {worst:.3f} |")
    largest = sorted(shifts, reverse=True)[:5]
    print("\nlargest mean shifts / U: "
          + ", ".join(f"{axis} {name} {shift:.3f}" for shift, axis, name in largest))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
