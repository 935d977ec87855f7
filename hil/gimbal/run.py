"""``gimbal-hil calibrate --gimbal``: each axis of the gimbal calibrated under its one serial,
in the gimbal profile's order, each by today's axis calibration in a process of its own
(its console output shown as it runs), into ``OUT/SERIAL/AXIS/SERIAL/``; one results store
for all of them (resolved once, as a one-axis calibration would); then the gimbal
certificate in ``OUT/SERIAL/`` (JSON, TXT, HTML, PDF). A refused or interrupted axis stops
the gimbal (the axes after it are not started); a failed one does not (the gimbal's picture
stays whole)."""

from __future__ import annotations

import signal
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

from hil.gimbal import certificate
from hil.gimbal.documents import write_documents
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
    try:
        for index, axis in enumerate(gimbal.axes, start=1):
            print(f"gimbal {serial}: axis {index} of {len(gimbal.axes)}, {axis.name}",
                  flush=True)
            written = folder / axis.name / serial / "certificate.json"
            before = _stamp(written)
            code = _calibrate_axis([
                sys.executable, "-m", "hil.cli", "calibrate", "--profile",
                str(axis.profile_path), "--unit-serial", serial, "--out",
                str(folder / axis.name), "--store", store_url, *options])
            codes.append(code)
            # only a certificate this run wrote (a refused axis leaves the last one there)
            fresh = written if _stamp(written) not in (None, before) else None
            outcomes.append(certificate.AxisOutcome(name=axis.name, certificate=fresh,
                                                    exit_code=code))
            if code in STOPS_THE_GIMBAL:
                break
    finally:
        for axis in gimbal.axes[len(outcomes):]:
            outcomes.append(certificate.AxisOutcome(name=axis.name, certificate=None,
                                                    exit_code=certificate.NOT_STARTED))
        issued = certificate.build(gimbal, serial=serial, folder=folder, axes=outcomes)
        json_path, _ = certificate.write(issued, folder)
        for problem in write_documents(json_path):
            print(f"gimbal {serial}: {problem}")
        each = ", ".join(f"{a['axis']} {a['outcome']}" for a in issued["axes"])
        print(f"gimbal {serial}: {issued['outcome']} ({each}) -> {json_path}")
    return max(codes, default=0) if any(codes) else 0


def _calibrate_axis(argv: list[str]) -> int:
    """Run one axis's calibration to its end, and its exit code. An interrupt (Ctrl-C) is
    passed on and waited out: the axis's calibration stops the drive, disables it and
    writes its aborted certificate (killing it would leave the drive as it was)."""
    process = subprocess.Popen(argv)
    while True:
        try:
            return process.wait()
        except KeyboardInterrupt:  # a second SIGINT while it stops is ignored there
            process.send_signal(signal.SIGINT)


def _stamp(path: Path) -> int | None:
    """A file's modification time (ns), ``None`` when it does not exist."""
    try:
        return path.stat().st_mtime_ns
    except FileNotFoundError:
        return None
