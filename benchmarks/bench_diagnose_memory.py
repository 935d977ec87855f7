"""``gimbal-hil diagnose``'s peak memory per sample, and the bound it is held to (issue 26,
item 15).

Each size runs in a fresh process (``ru_maxrss`` of that process: the recording read, the
diagnosis made, nothing written but the JSON), on the simulator's own recording of the
demo unit (``gimbal-hil simulate --duration N``, 4 kHz). The slope between two sizes is
the memory per sample; the intercept the fixed cost (imports, numba, the fits' constants).

Measured (2 cores, shared, Python 3.11), the bound in ``hil/diagnose/core.py``:

    rows      peak RSS   (reading alone)
    100,000   1,072 MB   147 MB
    200,000   1,521 MB   258 MB
    slope 4.5 kB/sample (reading 1.1 kB of it), intercept ~620 MB
    bound: DIAGNOSE_BYTES_PER_ROW = 8,192 B/sample against the memory budget
    (hil/budget.py: 50 % of physical memory, GIMBAL_HIL_MEMORY_BUDGET_MB overrides);
    a recording above it is refused while its rows are counted, before it is read whole.

    nice -n 10 python -m benchmarks.bench_diagnose_memory --seconds 25 50
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from hil.diagnose.core import DIAGNOSE_BYTES_PER_ROW

MEASURE = """
import resource, sys
from hil.recording import read_recording
from hil.diagnose.core import DIAGNOSE_BYTES_PER_ROW, diagnose
recording = read_recording(sys.argv[1], log_warnings=False,
                           bytes_per_row=DIAGNOSE_BYTES_PER_ROW)
read_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
diagnose(recording)
print(len(recording), read_kb, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def peak(path: Path) -> tuple[int, float, float]:
    """(rows, peak MiB after reading, peak MiB after diagnosing) in a fresh process."""
    done = subprocess.run([sys.executable, "-c", MEASURE, str(path)], capture_output=True,
                          text=True, check=True)
    rows, read_kb, total_kb = (int(v) for v in done.stdout.split()[-3:])
    return rows, read_kb / 1024, total_kb / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, nargs="+", default=[25.0, 50.0],
                        help="recording lengths at 4 kHz (default 25 50: 100 k, 200 k rows)")
    args = parser.parse_args()
    results = []
    with tempfile.TemporaryDirectory() as folder:
        for seconds in args.seconds:
            path = Path(folder) / f"rec_{seconds:g}.csv"
            subprocess.run([sys.executable, "-m", "hil.cli", "simulate", "--duration",
                            f"{seconds:g}", "--out", str(path)], check=True,
                           capture_output=True)
            rows, read_mib, total_mib = peak(path)
            results.append((rows, total_mib))
            print(f"{rows:>10,} rows  peak {total_mib:8,.0f} MiB  (reading {read_mib:,.0f} MiB)")
    if len(results) >= 2:
        (r0, m0), (r1, m1) = results[0], results[-1]
        slope = (m1 - m0) * 2**20 / (r1 - r0)
        print(f"slope {slope:,.0f} B/sample, intercept {m0 - slope * r0 / 2**20:,.0f} MiB; "
              f"bound {DIAGNOSE_BYTES_PER_ROW:,} B/sample "
              f"({'holds' if slope <= DIAGNOSE_BYTES_PER_ROW else 'EXCEEDED'})")


if __name__ == "__main__":
    main()
