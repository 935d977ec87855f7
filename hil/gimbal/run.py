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
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import FrameType

from hil.calibration import UnitLock, check_serial
from hil.gimbal import certificate
from hil.gimbal.documents import write_documents
from hil.gimbal.profile import GimbalProfile

#: pytest's exit codes after which the next axis is not started: interrupted, internal
#: error, usage error (a refusal before motion)
STOPS_THE_GIMBAL = (2, 3, 4)
STOP_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")  # each passed on to the running axis
INTERRUPTED = 2  # pytest's exit code of an interrupted run


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

    Raises
    ------
    InputError
        ``serial`` is no unit serial, or another gimbal calibration of it is writing
        ``out/serial`` (its lock, :class:`hil.calibration.UnitLock`): before any axis moves.
    """
    check_serial(serial)
    folder = out / serial
    lock = UnitLock.acquire(folder)  # one gimbal calibration per serial and folder at once
    try:
        return _each_axis(gimbal, serial=serial, folder=folder, store_url=store_url,
                          options=options)
    finally:
        lock.release()


def _each_axis(gimbal: GimbalProfile, *, serial: str, folder: Path, store_url: str,
               options: Sequence[str]) -> int:
    """Every axis in order, then the gimbal certificate (:func:`calibrate_gimbal`)."""
    outcomes, codes = [], []
    try:
        with _stops_as_interrupts():
            for index, axis in enumerate(gimbal.axes, start=1):
                print(f"gimbal {serial}: axis {index} of {len(gimbal.axes)}, {axis.name}",
                      flush=True)
                written = folder / axis.name / serial / "certificate.json"
                before = _stamp(written)
                siblings = [item for other in gimbal.axes if other is not axis
                            for item in ("--gimbal-axis", f"{other.name}={other.profile_path}")]
                code = _calibrate_axis([
                    sys.executable, "-m", "hil.cli", "calibrate", "--profile",
                    str(axis.profile_path), "--unit-serial", serial, "--out",
                    str(folder / axis.name), "--store", store_url, *siblings, *options])
                codes.append(code)
                # only a certificate this run wrote (a refused axis leaves the last one)
                fresh = written if _stamp(written) not in (None, before) else None
                outcomes.append(certificate.AxisOutcome(name=axis.name, certificate=fresh,
                                                        exit_code=code))
                if code in STOPS_THE_GIMBAL:
                    break
    except KeyboardInterrupt:  # between two axes: the next is not started
        codes.append(INTERRUPTED)
    finally:
        for axis in gimbal.axes[len(outcomes):]:
            outcomes.append(certificate.AxisOutcome(name=axis.name, certificate=None,
                                                    exit_code=certificate.NOT_STARTED))
        issued = certificate.build(gimbal, serial=serial, folder=folder, axes=outcomes)
        json_path, _ = certificate.write(issued, folder)
        for problem in write_documents(json_path):
            print(f"gimbal {serial}: {problem}")
        if store_url != "off":  # the axes' runs are stored by each axis's calibration
            from hil.store.record import record_run

            print(f"gimbal {serial}: {record_run(json_path, out_dir=folder.parent, url=store_url)}")
        each = ", ".join(f"{a['axis']} {a['outcome']}" for a in issued["axes"])
        print(f"gimbal {serial}: {issued['outcome']} ({each}) -> {json_path}")
    return max(codes, default=0)


def _calibrate_axis(argv: list[str]) -> int:
    """Run one axis's calibration to its end, and its exit code. A stop (Ctrl-C, or SIGTERM
    or SIGHUP sent to this process alone) is passed on and waited out: the axis's
    calibration stops the drive, disables it and writes its aborted certificate (killing
    it, or leaving it to run on, would not)."""
    process = subprocess.Popen(argv)
    while True:
        try:
            return process.wait()
        except KeyboardInterrupt:  # a second stop while it stops is ignored there
            process.send_signal(signal.SIGINT)


@contextmanager
def _stops_as_interrupts() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP raise ``KeyboardInterrupt`` here (the calibration
    treats the three alike), SIGINT even when this process started with it ignored; the
    earlier handlers come back after."""
    def interrupt(signum: int, _frame: FrameType | None) -> None:
        raise KeyboardInterrupt(signal.Signals(signum).name)

    numbers = [getattr(signal, name) for name in STOP_SIGNALS if hasattr(signal, name)]
    if threading.current_thread() is not threading.main_thread():
        yield  # handlers can be set from the main thread only
        return
    previous = {number: signal.signal(number, interrupt) for number in numbers}
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def _stamp(path: Path) -> int | None:
    """A file's modification time (ns), ``None`` when it does not exist."""
    try:
        return path.stat().st_mtime_ns
    except FileNotFoundError:
        return None
