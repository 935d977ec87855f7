"""The command line's start-up and the simulator end to end, as a user runs them (issue 24).

Two figures, each the median wall time of ``--runs`` fresh processes:

- ``gimbal-hil --help``: the start-up alone (the goal: under 0.3 s);
- ``gimbal-hil simulate --duration 120 --out TMP/rec.csv``: start-up, the numba kernel
  loaded from its on-disk cache, the run and the CSV written, as × real time (the goal:
  at least 50 ×, i.e. at most 2.4 s for 120 s). One unmeasured run first, so that a
  changed kernel's compilation is not counted (it is cached on disk for every later run).

The installed ``gimbal-hil`` script is timed when it is on PATH, else ``python -m hil.cli``.
The machine's load (1-minute load average before and after, cores) is printed with the
figures: on a shared machine they move with it.

    nice -n 10 python -m benchmarks.bench_cli --runs 7
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

SIMULATED_S = 120.0  # the README's `simulate --duration 120`
HELP_GOAL_S = 0.3
REAL_TIME_GOAL = 50.0


@dataclass(frozen=True, slots=True)
class Timing:
    """Wall times of one command over several fresh processes."""

    command: str
    walls_s: tuple[float, ...]
    cpus_s: tuple[float, ...]  # user + system of the process: less moved by others' load

    @property
    def median_s(self) -> float:
        return statistics.median(self.walls_s)

    @property
    def median_cpu_s(self) -> float:
        return statistics.median(self.cpus_s)


def command_prefix() -> list[str]:
    """The installed script, else the module through this interpreter."""
    script = shutil.which("gimbal-hil")
    return [script] if script else [sys.executable, "-m", "hil.cli"]


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def wall_and_cpu_s(argv: list[str]) -> tuple[float, float]:
    """One run's wall and CPU time; a failing command stops the benchmark."""
    cpu_before_s = _children_cpu_s()
    started = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, text=True, check=False)
    elapsed_s = time.perf_counter() - started
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} exited {done.returncode}: {done.stderr[-2000:]}")
    return elapsed_s, _children_cpu_s() - cpu_before_s


def timed(argv: list[str], shown: str, runs: int, *, warm_up: int = 1) -> Timing:
    """Wall and CPU times of ``runs`` processes after ``warm_up`` unmeasured ones."""
    for _ in range(warm_up):
        wall_and_cpu_s(argv)
    measured = [wall_and_cpu_s(argv) for _ in range(runs)]
    return Timing(command=shown, walls_s=tuple(w for w, _ in measured),
                  cpus_s=tuple(c for _, c in measured))


def paragraph(help_run: Timing, simulate: Timing, *, load_before: float, load_after: float,
              when: datetime) -> str:
    """The figures as a short markdown paragraph (for RESULTS.md)."""
    factor = SIMULATED_S / simulate.median_s
    spread = f"{min(simulate.walls_s):.2f}–{max(simulate.walls_s):.2f} s"
    return (
        f"**Command-line start-up** ({when:%Y-%m-%d}, {os.cpu_count()} cores, 1-minute load "
        f"average {load_before:.2f} before and {load_after:.2f} after; median of "
        f"{len(help_run.walls_s)} fresh processes each, `benchmarks/bench_cli.py`): "
        f"`{help_run.command}` {help_run.median_s:.3f} s "
        f"({min(help_run.walls_s):.3f}–{max(help_run.walls_s):.3f} s; CPU "
        f"{help_run.median_cpu_s:.3f} s; goal < {HELP_GOAL_S} s); `{simulate.command}` "
        f"{simulate.median_s:.2f} s ({spread}; CPU {simulate.median_cpu_s:.2f} s) end to end, "
        f"{factor:.0f} × real time (goal ≥ {REAL_TIME_GOAL:.0f} ×)."
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--runs", type=int, default=7,
                        help="measured processes per command (default: %(default)s)")
    parser.add_argument("--markdown", type=Path, default=None,
                        help="also write the paragraph here (default: printed only)")
    args = parser.parse_args()
    prefix = command_prefix()
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "rec.csv"
        help_run = timed([*prefix, "--help"], "gimbal-hil --help", args.runs)
        simulate = timed([*prefix, "simulate", "--duration", f"{SIMULATED_S:g}",
                          "--out", str(out)],
                         f"gimbal-hil simulate --duration {SIMULATED_S:g} --out TMP/rec.csv",
                         args.runs)
    text = paragraph(help_run, simulate, load_before=load_before,
                     load_after=os.getloadavg()[0], when=datetime.now(UTC))
    print(text)
    for timing in (help_run, simulate):
        print(f"  {timing.command}: wall " + ", ".join(f"{w:.3f}" for w in timing.walls_s)
              + " s; CPU " + ", ".join(f"{c:.3f}" for c in timing.cpus_s) + " s")
    if args.markdown is not None:
        args.markdown.write_text(text + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
