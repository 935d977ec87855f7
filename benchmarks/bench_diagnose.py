"""Wall time of ``diagnose`` on 64 000-sample recordings (target: ≤ 10 s each).

Run: ``python benchmarks/bench_diagnose.py [REC.csv.gz ...]`` (default: the shared examples).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from hil.diagnose.core import diagnose
from hil.diagnose.report import report
from hil.recording import read_recording

SHARED = Path(__file__).resolve().parents[2] / "shared" / "recordings"


def main(paths: list[str]) -> int:
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


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
