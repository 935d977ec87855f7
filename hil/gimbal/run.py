"""``gimbal-hil calibrate --gimbal``: each axis of the gimbal calibrated under its one serial,
in the gimbal profile's order, each by today's axis calibration in a process of its own
(its console output shown as it runs), into ``OUT/SERIAL/AXIS/SERIAL/``; one results store
for all of them (resolved once, as a one-axis calibration would); then the gimbal
certificate in ``OUT/SERIAL/``. A refused or interrupted axis stops the gimbal (the axes
after it are not started); a failed one does not (the gimbal's picture stays whole)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

from hil.gimbal import certificate
from hil.gimbal.profile import GimbalProfile

#: pytest's exit codes after which the next axis is not started: interrupted, internal
#: error, usage error (a refusal before motion)
STOPS_THE_GIMBAL = (2, 3, 4)


def calibrate_gimbal(gimbal: GimbalProfile, *, serial: str, out: Path, store_url: str,
                     options: Sequence[str]) -> int:
    """Calibrate every axis, write the gimbal certificate; the exit code.

    Parameters
    ----------
    gimbal : GimbalProfile
    serial : str
        The gimbal's serial (every axis's certificate carries it, with its axis).
    out : Path
        The certificates' folder; the gimbal's is ``out/serial``.
    store_url : str
        The results store every axis's run goes to (``off``: none).
    options : sequence of str
        ``calibrate`` options every axis takes (drive, station, seed, operator, …).

    Returns
    -------
    int
        0 when every axis's calibration returned 0; else the largest of their codes.
    """
    folder = out / serial
    folder.mkdir(parents=True, exist_ok=True)
    outcomes, codes = [], []
    for index, axis in enumerate(gimbal.axes, start=1):
        print(f"gimbal {serial}: axis {index} of {len(gimbal.axes)}, {axis.name}", flush=True)
        code = subprocess.call([
            sys.executable, "-m", "hil.cli", "calibrate", "--profile", str(axis.profile_path),
            "--unit-serial", serial, "--out", str(folder / axis.name), "--store", store_url,
            *options])
        codes.append(code)
        written = folder / axis.name / serial / "certificate.json"
        outcomes.append(certificate.AxisOutcome(
            name=axis.name, certificate=written if written.is_file() else None,
            exit_code=code))
        if code in STOPS_THE_GIMBAL:
            break
    for axis in gimbal.axes[len(outcomes):]:
        outcomes.append(certificate.AxisOutcome(name=axis.name, certificate=None,
                                                exit_code=certificate.NOT_STARTED))
    issued = certificate.build(gimbal, serial=serial, folder=folder, axes=outcomes)
    json_path, _ = certificate.write(issued, folder)
    each = ", ".join(f"{a['axis']} {a['outcome']}" for a in issued["axes"])
    print(f"gimbal {serial}: {issued['outcome']} ({each}) -> {json_path}")
    return max(codes, default=0) if any(codes) else 0
