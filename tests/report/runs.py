"""A calibration as an operator runs it: ``gimbal-hil calibrate`` in its own process."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from hil.characterise.processes import run_command


@dataclass(frozen=True)
class Run:
    unit_dir: Path
    stdout: str
    returncode: int


def calibrate(out: Path, serial: str, *args: str) -> Run:
    done = run_command(
        ["calibrate", "--drive", "sim", "--unit-serial", serial,
         "--out", str(out), *args],
        timeout_s=600,
    )
    return Run(unit_dir=out / serial, stdout=done.stdout + done.stderr,
               returncode=done.returncode)
