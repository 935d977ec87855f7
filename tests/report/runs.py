"""A calibration as an operator runs it: ``gimbal-hil calibrate`` in its own process."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Run:
    unit_dir: Path
    stdout: str
    returncode: int


def calibrate(out: Path, serial: str, *args: str) -> Run:
    done = subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--drive", "sim", "--unit-serial", serial,
         "--out", str(out), *args],
        capture_output=True, text=True, timeout=600, check=False,
    )
    return Run(unit_dir=out / serial, stdout=done.stdout + done.stderr,
               returncode=done.returncode)
