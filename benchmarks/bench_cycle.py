"""End-of-line cycle time: each protocol's commanded motion and every result's expanded
uncertainty, on both demo units, for this tree and an earlier revision of it.

    git archive REV | tar -x -C /tmp/before        # the revision to compare against
    python -m benchmarks.bench_cycle --before /tmp/before --seeds 1 2 3 4 5 6 7 8

Each tree calibrates each demo profile once per seed through the command line
(``gimbal-hil calibrate --store off -- --no-documents``), on the simulator and, with
``--canopen-seeds``, over the CANopen emulator. A single certificate's U is itself a
random draw (a Type A from 4–20 degrees of freedom scatters by 15–35 %), so the table
compares the **median** U over the seeds, and states how far two halves of the *same*
tree's seeds already differ (``chance``): a ratio inside that is no evidence of a change.
Motion is commanded time (the certificate's ``motion_time_s``), which does not depend on
the seed.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

PROFILES = {"elevation": "demo_gimbal_elevation", "azimuth": "demo_gimbal_azimuth"}
PACKAGES = {"hil": "hil", "plant_sim": "plant_sim", "gimbal_hil_protocols": "protocols",
            "gimbal_hil_fixtures": "fixtures"}
HERE = Path(__file__).resolve().parent.parent


@dataclass(frozen=True, slots=True)
class Run:
    """One calibration: which tree, profile, drive and seed; where its certificate is."""

    tree: str
    axis: str
    drive: str
    seed: int
    certificate: Path


def import_path(tree: Path, out: Path) -> Path:
    """A directory of links that makes ``tree``'s packages importable under their installed
    names (as the worktrees' ``.pp``), so neither tree runs the installed package."""
    links = out / "pythonpath"
    links.mkdir(parents=True, exist_ok=True)
    for name, folder in PACKAGES.items():
        link = links / name
        if link.is_symlink() or link.exists():
            link.unlink()
        link.symlink_to(tree.resolve() / folder)
    return links


def calibrate(run: Run, *, tree: Path, links: Path) -> None:
    """Calibrate one demo unit with ``tree``'s code; the certificate lands at
    ``run.certificate``."""
    out = run.certificate.parent.parent
    serial = run.certificate.parent.name
    env = {**os.environ, "PYTHONPATH": str(links)}
    subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--drive", run.drive,
         "--profile", PROFILES[run.axis], "--unit-serial", serial, "--seed", str(run.seed),
         "--store", "off", "--out", str(out), "--", "--no-documents", "-p", "no:cacheprovider"],
        cwd=tree, env=env, check=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )


def plan_runs(out: Path, seeds: Sequence[int], canopen_seeds: Sequence[int]) -> list[Run]:
    runs = []
    for tree in ("before", "after"):
        for axis in PROFILES:
            for drive, chosen in (("sim", seeds), ("canopen-emulator", canopen_seeds)):
                for seed in chosen:
                    serial = f"{axis[:2].upper()}-{drive.split('-')[0]}-{seed}"
                    runs.append(Run(tree, axis, drive, seed,
                                    out / tree / drive / serial / "certificate.json"))
    return runs


def load(run: Run) -> dict[str, Any] | None:
    if not run.certificate.exists():
        return None
    document: dict[str, Any] = json.loads(run.certificate.read_text(encoding="utf-8"))
    return document


def median_u(certificates: Sequence[dict[str, Any]]) -> dict[str, float]:
    """Median expanded uncertainty of each result over the certificates."""
    found: dict[str, list[float]] = {}
    for c in certificates:
        for r in c["results"]:
            found.setdefault(r["parameter"], []).append(float(r["expanded_uncertainty"]))
    return {p: statistics.median(v) for p, v in found.items()}


def motion(certificates: Sequence[dict[str, Any]]) -> dict[str, float]:
    """Commanded motion per protocol (the first certificate's; the seed does not change it)."""
    if not certificates:
        return {}
    return {name: float(p["motion_time_s"])
            for name, p in certificates[0]["method"]["protocols"].items()
            if p["outcome"] != "SKIPPED"}


def chance(certificates: Sequence[dict[str, Any]]) -> dict[str, float]:
    """How far the median U of two halves of one tree's seeds differ (max/min), per result:
    the ratio a comparison of medians shows with nothing changed."""
    first, second = median_u(certificates[0::2]), median_u(certificates[1::2])
    return {p: max(first[p], second[p]) / min(first[p], second[p])
            for p in first if p in second and min(first[p], second[p]) > 0}


def table(axis: str, drive: str, before: list[dict[str, Any]], after: list[dict[str, Any]]
          ) -> list[str]:
    """The markdown table of one demo unit on one drive."""
    mb, ma = motion(before), motion(after)
    ub, ua = median_u(before), median_u(after)
    noise = chance(before) if len(before) >= 4 else {}
    protocol_of = {r["parameter"]: r["protocol"] for c in after + before for r in c["results"]}
    outcomes_b = ", ".join(c["outcome"] for c in before)
    outcomes_a = ", ".join(c["outcome"] for c in after)
    lines = [f"**{axis}, {drive}** ({len(before)} / {len(after)} calibrations; motion "
             f"{sum(mb.values()):.1f} s → {sum(ma.values()):.1f} s; outcomes before: "
             f"{outcomes_b}; after: {outcomes_a})", "",
             "| protocol | motion before (s) | after (s) | result | median U before | after "
             "| after / before | chance |", "|---|---|---|---|---|---|---|---|"]
    for name in dict.fromkeys([*mb, *ma]):
        results = [p for p, proto in protocol_of.items() if proto == name]
        first = True
        for p in results or [""]:
            cells = ([name, f"{mb.get(name, 0.0):.1f}", f"{ma.get(name, 0.0):.1f}"] if first
                     else ["", "", ""])
            first = False
            if p and p in ub and p in ua:
                ratio = ua[p] / ub[p]
                cells += [p, f"{ub[p]:.3g}", f"{ua[p]:.3g}", f"{ratio:.2f}",
                          f"{noise[p]:.2f}" if p in noise else "–"]
            else:
                cells += [p, "", "", "", ""]
            lines.append("| " + " | ".join(cells) + " |")
    lines.append(f"| **total** | **{sum(mb.values()):.1f}** | **{sum(ma.values()):.1f}** "
                 "| | | | | |")
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", type=Path, required=True,
                        help="source tree of the revision to compare against")
    parser.add_argument("--after", type=Path, default=HERE, help="source tree (default: this)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5, 6, 7, 8])
    parser.add_argument("--canopen-seeds", type=int, nargs="*", default=[1])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("cycle-run"))
    parser.add_argument("--reuse", action="store_true",
                        help="only read the certificates under --out, calibrate nothing")
    parser.add_argument("--markdown", type=Path, default=None)
    args = parser.parse_args()
    for tree in (args.before, args.after):
        if not (tree / "hil").is_dir() or not (tree / "fixtures").is_dir():
            print(f"bench_cycle: {tree} is not a gimbal-hil source tree (no hil/, fixtures/)",
                  file=sys.stderr)
            return 2
    runs = plan_runs(args.out, args.seeds, args.canopen_seeds)
    # a certificate already under --out is read, not made again (delete --out to start over)
    pending = [] if args.reuse else [r for r in runs if not r.certificate.exists()]
    if pending:
        trees = {"before": args.before, "after": args.after}
        links = {name: import_path(tree, args.out / name) for name, tree in trees.items()}
        with ThreadPoolExecutor(args.workers) as pool:
            list(pool.map(lambda r: calibrate(r, tree=trees[r.tree], links=links[r.tree]),
                          pending))
    lines: list[str] = []
    for drive in ("sim", "canopen-emulator"):
        for axis in PROFILES:
            done = {tree: [c for r in runs if (r.tree, r.axis, r.drive) == (tree, axis, drive)
                           if (c := load(r)) is not None]
                    for tree in ("before", "after")}
            if done["before"] and done["after"]:
                lines += [*table(axis, drive, done["before"], done["after"]), ""]
    text = "\n".join(lines)
    print(text)
    if args.markdown is not None:
        args.markdown.write_text(text + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
