"""``gimbal-hil diagnose``: wall time per recording, and recovery over hidden effects.

Run:

- ``python -m benchmarks.bench_diagnose [REC.csv.gz ...]``: wall time of ``diagnose`` on each
  recording (default: the shared examples, 64 000 samples each; target ≤ 10 s each).
- ``python -m benchmarks.bench_diagnose --hidden N [--pairs] [--unknown] [--seed S]``: N
  simulated units (``tests/diagnose/diagnose_simdata.py``), each with one hidden effect,
  two (``--pairs``: every unordered pair of the seven effects in turn) or one effect outside
  the library (``--unknown``), sizes drawn (``--only E ...``: only those single effects;
  ``--pairs --with E ...``: only the pairs holding one of those, the same draws);
  prints, per case, what was named, and the rates: every hidden effect named with its key
  parameter within 15 %, nothing else named, the 95 % intervals' coverage of the truth,
  and ``unexplained`` flags.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from hil.diagnose.core import diagnose
from hil.diagnose.report import report
from hil.recording import Recording, read_recording

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "recordings"

SEVEN = ("stribeck", "cogging", "kt_ripple", "gravity", "cable_spring", "current_lag",
         "two_mass")
SINGLE = ("offset", "asymmetric_friction", *SEVEN)
UNKNOWN = ("friction_bump", "backlash", "cubic_spring")


def speed(paths: list[str]) -> int:
    files = [Path(p) for p in paths] or sorted(SHARED.glob("example_*.csv.gz"))
    worst = 0.0
    for path in files:
        recording = read_recording(path)
        started = time.perf_counter()
        data = report(diagnose(recording))
        elapsed = time.perf_counter() - started
        worst = max(worst, elapsed)
        names = ", ".join(c["name"] for c in data["causes"]) or "none"
        print(f"{path.name}: {len(recording)} samples, {elapsed:.2f} s, causes: {names}")
    print(f"worst {worst:.2f} s (target 10 s)")
    return 0 if worst <= 10.0 else 1


def _interval(cause: dict[str, Any], key: str) -> list[float] | None:
    entry = cause.get("uncertainty", {}).get(key)
    return None if entry is None else entry.get("ci95")


def _found(data: dict[str, Any]) -> list[str]:
    """The structure tests that found what the final model leaves."""
    return [name for name, test in data["unexplained_structure"]["tests"].items()
            if test["found"]]


def declared_alias(data: dict[str, Any], effect: str, key: str, truth: float) -> bool:
    """Whether a named cause declares ``effect`` not separable from it, with an interval of
    ``effect``'s ``key`` that holds ``truth`` (the pairs test's rule, docs/diagnose.md)."""
    for cause in data["causes"]:
        other = cause.get("not_separable_from", {}).get(effect)
        if cause.get("separable") is False and other is not None:
            interval = other["uncertainty"].get(key, {}).get("ci95")
            if interval is not None and interval[0] <= truth <= interval[1]:
                return True
    return False


def recording_labels(variant: Any) -> str:
    return ", ".join(variant.labels().values())


def hidden(count: int, *, pairs: bool, unknown: bool, seed: int,
           only: tuple[str, ...] = (), first: int = 0, with_: tuple[str, ...] = (),
           variants: bool = False, cutoff_hz: float | None = None) -> int:
    from plant_sim.variant import UnstableLoopError, Variant, draw_variant
    from tests.diagnose.diagnose_simdata import observable, plant_with, record
    from tests.diagnose.unknown_effects import hide_unknown

    variant_rng = np.random.default_rng(seed + 1_000_003)  # apart: the unit draws stay
    per_variant: dict[str, Counter[str]] = {}

    def recorded(params: Any, run_seed: int) -> tuple[Recording, Variant | None]:
        """The case's recording: with ``--variants`` by a drawn variant (one whose loop
        loses the unit is drawn again)."""
        while variants:
            variant = draw_variant(variant_rng)
            try:
                return record(params, seed=run_seed, variant=variant), variant
            except UnstableLoopError:
                stats["variants_redrawn"] += 1
        return record(params, seed=run_seed), None

    rng = np.random.default_rng(seed)
    combos: list[tuple[str, ...]]
    if unknown:
        combos = [(u,) for u in UNKNOWN]
    elif pairs:
        combos = list(itertools.combinations(SEVEN, 2))
    else:
        combos = [(e,) for e in (only or SINGLE)]
    stats: Counter[str] = Counter()
    per_effect: Counter[str] = Counter()
    per_effect_ok: Counter[str] = Counter()
    per_effect_intervals: Counter[str] = Counter()
    per_effect_covered: Counter[str] = Counter()
    z_scores: list[float] = []
    started = time.perf_counter()
    skipped = 0
    for case in range(count):
        effects = combos[case % len(combos)]
        inertia, viscous, coulomb = (rng.uniform(0.002, 0.006), rng.uniform(0.003, 0.008),
                                     rng.uniform(0.015, 0.03))
        order = int(rng.integers(24, 121))
        run_seed = int(rng.integers(0, 2**16))
        skip = case < first or bool(with_ and not set(with_) & set(effects))
        if skip:  # skipped: its draws taken all the same
            skipped += 1
            rng.uniform(size=2 * (1 if unknown else len(effects)))
            continue
        if unknown:
            base = plant_with(inertia, viscous, coulomb, (), order)
            recording, variant = recorded(base.params, run_seed)
            recording = hide_unknown(recording, effects[0],
                                     size=float(rng.uniform()), detail=float(rng.uniform()))
            data = report(diagnose(recording, cutoff_hz=cutoff_hz))
            names = [c["name"] for c in data["causes"] if "part_of" not in c]
            ok = data["unexplained"] and not names
            stats["unexplained"] += data["unexplained"]
            stats["nothing_named"] += not names
            stats["ok"] += ok
            print(f"{case:3d} {effects[0]:14s} named {names} unexplained {data['unexplained']} "
                  f"{data['unexplained_structure']['where']}", flush=True)
            continue
        drawn = tuple((e, float(rng.uniform()), float(rng.uniform())) for e in effects)
        hidden_set = plant_with(inertia, viscous, coulomb, drawn, order)
        recording, variant = recorded(hidden_set.params, run_seed)
        data = report(diagnose(recording, cutoff_hz=cutoff_hz))
        # a part of the cause before it (an asymmetric friction's constant) is not a cause
        causes = {c["name"]: c for c in data["causes"] if "part_of" not in c}
        truths = observable(hidden_set.truths, variant)
        hidden_names = {t.effect for t in truths}
        declared = [f"{n}~{o}(dBIC {a['delta_bic']}, instead {a['instead_delta_bic']}, "
                    f"VIF {a['inflation']})"
                    for n, c in causes.items()
                    for o, a in c.get("not_separable_from", {}).items()]
        stats["declared_not_separable"] += bool(declared)
        all_ok = True
        notes = []
        for truth in truths:
            per_effect[truth.effect] += 1
            cause = causes.get(truth.effect)
            if cause is None:
                alias_ok = declared_alias(data, truth.effect, truth.key, truth.truth)
                all_ok &= alias_ok
                per_effect_ok[truth.effect] += alias_ok
                stats["recovered_by_declaration"] += alias_ok
                notes.append(f"{truth.effect} unnamed"
                             f"{' (declared not separable, interval holds)' if alias_ok else ''}")
                continue
            value = cause["parameters"][truth.key]
            within = math.isclose(value, truth.truth, rel_tol=0.15)
            interval = _interval(cause, truth.key)
            flagged = cause.get("separable") is False
            if interval is not None and all(x is not None and math.isfinite(x) for x in interval):
                covered = interval[0] <= truth.truth <= interval[1]
                stats["intervals"] += 1
                stats["covered"] += covered
                per_effect_intervals[truth.effect] += 1
                per_effect_covered[truth.effect] += covered
                std = cause["uncertainty"].get(truth.key, {}).get("std")
                # err/u where the interval is value ± k·u (not a profile likelihood's)
                centred = math.isclose(interval[1] - value, value - interval[0], rel_tol=1e-6)
                if std and (centred or not flagged):
                    z_scores.append((value - truth.truth) / std)
                    notes.append(f"err/u {(value - truth.truth) / std:+.2f}"
                                 f"{'' if covered else ' MISSED'}")
            good = within or (flagged and interval is not None
                              and interval[0] <= truth.truth <= interval[1])
            per_effect_ok[truth.effect] += good
            all_ok &= good
            notes.append(f"{truth.effect} {truth.key} {value:.4g}/{truth.truth:.4g}"
                         f"{' (not separable)' if flagged else ''}")
        # a cause that declares itself not separable from a hidden effect is its alias
        extra = [n for n in causes if n not in hidden_names
                 and not hidden_names & set(causes[n].get("not_separable_from", {}))]
        stats["cases"] += 1
        stats["all_named_within_15pct"] += all_ok
        stats["nothing_else_named"] += not extra
        stats["ok"] += all_ok and not extra
        stats["unexplained"] += data["unexplained"]
        for label in variant.labels().items() if variant else ():
            tally = per_variant.setdefault(": ".join(label), Counter())
            tally["cases"] += 1
            tally["ok"] += all_ok and not extra
        print(f"{case:3d} {'+'.join(effects):24s} {'ok  ' if all_ok and not extra else 'FAIL'} "
              f"named {list(causes)} {'; '.join(notes)}"
              f"{' EXTRA ' + str(extra) if extra else ''}"
              f"{' ALIAS ' + ','.join(declared) if declared else ''}"
              f"{' UNEXPLAINED ' + str(_found(data)) if data['unexplained'] else ''}"
              f"{' VARIANT ' + recording_labels(variant) if variant else ''}",
              flush=True)
    elapsed = time.perf_counter() - started
    summary: dict[str, Any] = dict(stats)
    summary["per_effect_named_within_15pct"] = {
        e: f"{per_effect_ok[e]}/{per_effect[e]}" for e in per_effect}
    summary["per_effect_intervals_holding_truth"] = {
        e: f"{per_effect_covered[e]}/{per_effect_intervals[e]}" for e in per_effect_intervals}
    if z_scores:
        summary["z_rms"] = float(np.sqrt(np.mean(np.square(z_scores))))
    if per_variant:
        summary["ok_per_variant"] = {k: f"{v['ok']}/{v['cases']}"
                                     for k, v in sorted(per_variant.items())}
    summary["seconds_per_case"] = elapsed / max(count - skipped, 1)
    print(json.dumps(summary, indent=1))
    return 0


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("paths", nargs="*")
    parser.add_argument("--hidden", type=int, default=0)
    parser.add_argument("--pairs", action="store_true")
    parser.add_argument("--unknown", action="store_true")
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--first", type=int, default=0,
                        help="skip the cases before this one (their draws are taken)")
    parser.add_argument("--with", dest="with_", nargs="*", default=[], choices=SEVEN,
                        help="--pairs: only the pairs holding one of these (draws taken)")
    parser.add_argument("--variants", action="store_true",
                        help="simulate each case with plant_sim.variant, its choices drawn")
    parser.add_argument("--cutoff-hz", type=float, default=None,
                        help="the diagnoser's analysis bandwidth (default: its own)")
    parser.add_argument("--only", nargs="*", default=[], choices=SINGLE,
                        help="single effects to hide (default: all nine in turn)")
    args = parser.parse_args(argv)
    if args.hidden:
        return hidden(args.hidden, pairs=args.pairs, unknown=args.unknown, seed=args.seed,
                      only=tuple(args.only), first=args.first, with_=tuple(args.with_),
                      variants=args.variants, cutoff_hz=args.cutoff_hz)
    return speed(args.paths)


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
