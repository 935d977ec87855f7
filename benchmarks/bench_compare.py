"""False alarms and detection power of ``gimbal-hil compare`` on the simulator.

    nice -n 10 python -m benchmarks.bench_compare --pairs 30 --reps 12 --out /tmp/bench-compare

0. With ``--write-map``: ``--map-pairs`` identical-firmware pairs (seeds 1000 + 2i,
   1001 + 2i) measure each result's run-to-run scatter beyond its budget; where the RMS of
   ``Δ/u(Δ)`` exceeds its χ² 95 % bound, the excess per run goes into the repeatability
   map (``fixtures/compare_repeatability.toml``) that ``gimbal-hil compare`` applies.
1. Identical firmware, different noise seeds, out of sample: ``--pairs`` independent pairs
   of calibrations of the demo elevation unit (seeds 3000 + 2i, 3001 + 2i), each pair
   compared with the map; the fraction that flags nothing (goal ≥ 19/20) and which results
   the others flagged.
2. Detection power: a candidate with the velocity loop's gain (Kp and Ki together) at
   ``--gain-factors`` of today's, ``--reps`` times each with a fresh seed, each compared
   with one of the out-of-sample pairs' baselines; the fraction flagged, and the smallest
   change found at least 95 % of the time. The same for the current loop made slower
   (``--tau-factors``), the one firmware setting today's suite measures directly.

Every firmware edit goes through ``tests/compare/firmware_variants.py`` (the settings
move from ``[plant]`` to ``[firmware]`` with issue 11's firmware work). Prints a markdown
table for ``benchmarks/RESULTS.md``; ``--reuse`` re-reads certificates already under
``--out`` instead of calibrating; ``--jobs N`` runs N calibrations at once (each is one
process; on a shared machine leave a core free).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w
from scipy import stats

from hil.compare.certificates import load_side
from hil.compare.repeatability import (
    NO_MAP,
    RepeatabilityMap,
    load_repeatability,
)
from hil.compare.verdict import Comparison, compare_sides
from tests.compare.firmware_variants import (
    firmware_setting,
    with_firmware,
    write_profile,
)

ROOT = Path(__file__).resolve().parents[1]
PROFILE = "demo_gimbal_elevation"
SERIAL = "BENCH-1"
GOAL_QUIET = 19 / 20
POWER = 0.95


def calibrate(changes: dict[str, float], out: Path, *, seed: int, reuse: bool) -> Path:
    """One calibration of the demo unit with ``changes`` to its firmware; its directory."""
    path = out / SERIAL / "certificate.json"
    if reuse and path.is_file():
        return out
    profile = write_profile(with_firmware(PROFILE, **changes), out / "profile.toml")
    done = subprocess.run(  # no results store, no PDF/HTML: compare reads the JSON only
        [sys.executable, "-m", "hil.cli", "calibrate", "--drive", "sim", "--profile",
         str(profile), "--unit-serial", SERIAL, "--seed", str(seed), "--out", str(out),
         "--", "--store", "off", "--no-documents"],
        capture_output=True, check=False, env={**os.environ, "PYTHONHASHSEED": "0"},
        text=True,
    )
    if not path.is_file():
        (out / "calibrate.log").write_text(done.stdout + done.stderr, encoding="utf-8")
        raise SystemExit(f"{out}: calibration wrote no certificate (see calibrate.log)")
    if json.loads(path.read_text(encoding="utf-8"))["aborted"]:
        raise SystemExit(f"{path}: an aborted calibration (delete it and run again)")
    return out


Planned = tuple[dict[str, float], Path, int]


def planned(args: argparse.Namespace) -> list[Planned]:
    """Every calibration :func:`main` makes: (firmware changes, folder, seed)."""
    jobs: list[Planned] = []
    firsts = ([1000] if args.write_map is not None else []) + [3000]
    for first, count in zip(firsts, ([args.map_pairs] if args.write_map is not None else [])
                            + [args.pairs], strict=True):
        jobs += [({}, args.out / f"same-{s}", s)
                 for i in range(count) for s in (first + 2 * i, first + 2 * i + 1)]
    for keys, factor in power_changes(args):
        for r in range(args.reps):
            seed = power_seed(r, factor)
            jobs.append((scaled(keys, factor), args.out / f"{keys[0]}-{factor:g}-{seed}", seed))
    return jobs


def calibrate_all(plan: list[Planned], *, jobs: int, reuse: bool) -> None:
    """Make every planned calibration, ``jobs`` at a time."""
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        list(pool.map(lambda job: calibrate(job[0], job[1], seed=job[2], reuse=reuse), plan))


def power_changes(args: argparse.Namespace) -> list[tuple[tuple[str, ...], float]]:
    """(firmware keys scaled together, factor) of each detection-power row."""
    return ([(("velocity_kp_nm_s_rad", "velocity_ki_nm_rad"), f) for f in args.gain_factors]
            + [(("current_loop_time_constant_s",), f) for f in args.tau_factors])


def power_seed(rep: int, factor: float) -> int:
    """The candidate's noise seed for repetition ``rep`` of a change by ``factor``."""
    return 5000 + 100 * rep + round(100 * factor)


def scaled(keys: tuple[str, ...], factor: float) -> dict[str, float]:
    return {key: factor * float(firmware_setting(PROFILE, key)) for key in keys}


def compared(baseline: Path, candidate: Path, repeatability: RepeatabilityMap) -> Comparison:
    return compare_sides(load_side(baseline), load_side(candidate),
                         repeatability=repeatability)


def pair_dirs(out: Path, first_seed: int, pairs: int, *, reuse: bool
              ) -> list[tuple[Path, Path]]:
    """Identical-firmware pairs of calibrations (seeds first + 2i, first + 2i + 1)."""
    return [tuple(calibrate({}, out / f"same-{s}", seed=s, reuse=reuse)  # type: ignore[misc]
                  for s in (first_seed + 2 * i, first_seed + 2 * i + 1))
            for i in range(pairs)]


def write_map(pairs: list[tuple[Path, Path]], path: Path) -> dict[str, Any]:
    """Each result's run-to-run scatter beyond its budget, where significant (χ² 95 %)."""
    deltas: dict[str, list[tuple[float, float, float]]] = {}
    for first, second in pairs:
        for row in compared(first, second, NO_MAP).rows:
            if row.budget is not None and row.difference is not None and row.baseline:
                deltas.setdefault(row.parameter, []).append(
                    (row.difference, row.budget.standard_uncertainty, row.baseline.value))
    entries: dict[str, Any] = {}
    for name, rows in deltas.items():
        d, u, v = (np.array(x) for x in zip(*rows, strict=True))
        n = len(d)
        rms_z = math.sqrt(float(np.mean((d / u) ** 2)))
        if rms_z <= math.sqrt(stats.chi2.ppf(0.95, n) / n):
            continue
        excess = math.sqrt(max(float(np.mean(d**2) - np.mean(u**2)) / 2, 0.0))
        relative = abs(float(np.mean(v))) > 10 * float(np.std(v))
        entries[name] = {"scale": "relative" if relative else "absolute",
                         "scatter": excess / abs(float(np.mean(v))) if relative else excess,
                         "pairs": n, "rms_z_without": round(rms_z, 2)}
    document = {"population": f"{PROFILE}, {len(pairs)} identical-firmware pairs",
                "results": {"elevation": {k: {key: e[key] for key in ("scale", "scatter",
                                                                        "pairs")}
                                          for k, e in entries.items()}}}
    path.write_text(MAP_HEADER + tomli_w.dumps(document), encoding="utf-8")
    return entries


MAP_HEADER = """\
# Run-to-run scatter beyond each result's stated budget, per axis, written by
# benchmarks/bench_compare.py --write-map (see benchmarks/RESULTS.md). Only results whose
# identical-firmware reruns scatter significantly more than their budgets (RMS of Δ/u(Δ)
# above its χ² 95 % bound) have an entry; gimbal-hil compare adds it to each run as an
# independent line of the difference's budget.
"""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pairs", type=int, default=20, help="out-of-sample pairs")
    parser.add_argument("--map-pairs", type=int, default=20)
    parser.add_argument("--write-map", type=Path, default=None,
                        help="measure the repeatability map on --map-pairs and write it")
    parser.add_argument("--reps", type=int, default=12, help="candidates per change size")
    parser.add_argument("--gain-factors", type=float, nargs="+", default=[0.8, 0.7, 0.6, 0.5])
    parser.add_argument("--tau-factors", type=float, nargs="+", default=[1.02, 1.03, 1.05])
    parser.add_argument("--out", type=Path, default=Path("compare-run"))
    parser.add_argument("--reuse", action="store_true")
    parser.add_argument("--jobs", type=int, default=1, help="calibrations at once")
    args = parser.parse_args()
    started = time.perf_counter()
    if args.jobs > 1:  # every calibration first, N at a time; the steps below re-read them
        calibrate_all(planned(args), jobs=args.jobs, reuse=args.reuse)
        args.reuse = True
    repeatability, map_entries = load_repeatability(), {}
    if args.write_map is not None:
        map_entries = write_map(pair_dirs(args.out, 1000, args.map_pairs, reuse=args.reuse),
                                args.write_map)
        repeatability = load_repeatability(args.write_map)
    pairs = pair_dirs(args.out, 3000, args.pairs, reuse=args.reuse)
    baselines = [first for first, _ in pairs]
    quiet = 0
    flagged_by: Counter[str] = Counter()
    for first, second in pairs:
        comparison = compared(first, second, repeatability)
        quiet += comparison.exit_code == 0
        flagged_by.update(r.parameter for r in comparison.flagged())
    power: list[dict[str, Any]] = []
    labels = {"velocity_kp_nm_s_rad": "velocity gain (Kp, Ki)",
              "current_loop_time_constant_s": "current-loop time constant"}
    for keys, factor in power_changes(args):
        label = labels[keys[0]]
        found = 0
        which: Counter[str] = Counter()
        for r in range(args.reps):
            seed = power_seed(r, factor)
            name = f"{keys[0]}-{factor:g}-{seed}"
            candidate = calibrate(scaled(keys, factor), args.out / name, seed=seed,
                                  reuse=args.reuse)
            comparison = compared(baselines[r % len(baselines)], candidate, repeatability)
            found += comparison.exit_code == 1
            which.update(f"{row.parameter} {row.verdict.value}" for row in comparison.flagged())
        power.append({"change": label, "factor": factor, "found": found, "reps": args.reps,
                      "flagged": dict(which)})
    report = {"pairs": args.pairs, "quiet": quiet, "map": map_entries,
              "false_alarms_by_result": dict(flagged_by),
              "power": power, "wall_s": time.perf_counter() - started,
              "cpu_s": resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime}
    (args.out / "bench_compare.json").write_text(json.dumps(report, indent=2) + "\n")
    print(markdown(report))
    return 0 if quiet >= GOAL_QUIET * args.pairs else 1


def markdown(report: dict[str, Any]) -> str:
    pairs, quiet = report["pairs"], report["quiet"]
    alarms = ", ".join(f"{k} ×{v}" for k, v in report["false_alarms_by_result"].items())
    lines = [f"Repeatability map: {name} +{100 * e['scatter']:.2g} %"
             if e["scale"] == "relative" else f"Repeatability map: {name} +{e['scatter']:.2g}"
             for name, e in report.get("map", {}).items()]
    lines += [
        f"Identical firmware, different seeds: **{quiet}/{pairs}** comparisons flag nothing "
        f"(goal ≥ 19/20 = {GOAL_QUIET * pairs:.1f}/{pairs})"
        + (f"; flagged: {alarms}." if alarms else "."),
        "",
        "| change | factor of today's | found (exit 1) | what was flagged |",
        "|---|---|---|---|",
    ]
    smallest: dict[str, float] = {}
    for row in report["power"]:
        flagged = ", ".join(f"{k} ×{v}" for k, v in sorted(row["flagged"].items())) or "—"
        lines.append(f"| {row['change']} | {row['factor']:g} | {row['found']}/{row['reps']} | "
                     f"{flagged} |")
        if row["found"] >= POWER * row["reps"]:
            size = abs(row["factor"] - 1)
            smallest[row["change"]] = min(smallest.get(row["change"], size), size)
    lines.append("")
    for change in dict.fromkeys(r["change"] for r in report["power"]):
        found = smallest.get(change)
        lines.append(f"Smallest {change} change found ≥ 95 % of the time: "
                     + (f"{100 * found:.0f} %." if found is not None else "none of those tried."))
    lines.append(f"\nWall time {report['wall_s'] / 60:.1f} min, calibrations' CPU "
                 f"{report.get('cpu_s', float('nan')) / 60:.1f} min.")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
