"""``gimbal-hil calibrate --gimbal``: each axis of the gimbal calibrated under its one serial,
in the gimbal profile's order, each by today's axis calibration in a process of its own
(its console output shown as it runs), into ``OUT/SERIAL/AXIS/SERIAL/``; one results store
for all of them (resolved once, as a one-axis calibration would); then the gimbal
certificate in ``OUT/SERIAL/`` (JSON, TXT, HTML, PDF). A refused or interrupted axis stops
the gimbal (the axes after it are not started); a failed one does not (the gimbal's picture
stays whole). With ``--together`` (the simulator) both axes' processes run at once on one
shared gimbal, each line of their output after its axis's name; a stop reaches both."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import FrameType
from typing import Any

from hil.calibration import UnitLock, check_serial
from hil.drives.connect import INNER_AXIS as INNER
from hil.drives.connect import OUTER_AXIS as OUTER
from hil.errors import InputError
from hil.gimbal import certificate
from hil.gimbal.documents import write_documents
from hil.gimbal.profile import GimbalAxis, GimbalProfile

#: pytest's exit codes after which the next axis is not started: interrupted, internal
#: error, usage error (a refusal before motion)
STOPS_THE_GIMBAL = (2, 3, 4)
STOP_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")  # each passed on to the running axis
INTERRUPTED = 2  # pytest's exit code of an interrupted run


def calibrate_gimbal(gimbal: GimbalProfile, *, serial: str, out: Path, store_url: str,
                     options: Sequence[str], together: bool = False) -> int:
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
    together : bool
        Calibrate the axes at the same time on one shared simulated gimbal
        (:mod:`hil.drives.shared_gimbal`): each protocol beside the other axis's where
        neither disturbs the other (:mod:`hil.beside`), else one after the other.

    Returns
    -------
    int
        0 when every axis's calibration returned 0; else the largest of their codes.

    Raises
    ------
    InputError
        ``serial`` is no unit serial, or another gimbal calibration of it is writing
        ``out/serial`` (its lock, :class:`hil.calibration.UnitLock`): before any axis moves;
        ``together`` on a drive other than the simulator, or a gimbal other than an
        azimuth carrying an elevation.
    """
    check_serial(serial)
    if together:
        _check_together(gimbal, options)
    folder = out / serial
    lock = UnitLock.acquire(folder)  # one gimbal calibration per serial and folder at once
    try:
        each = _axes_together if together else _each_axis
        return each(gimbal, serial=serial, folder=folder, store_url=store_url,
                    options=options)
    finally:
        lock.release()


def _axis_argv(gimbal: GimbalProfile, axis: GimbalAxis, *, serial: str, folder: Path,
               store_url: str, options: Sequence[str], link: str | None = None) -> list[str]:
    """The ``calibrate`` command of one axis of the gimbal (the others as its siblings)."""
    siblings = [item for other in gimbal.axes if other is not axis
                for item in ("--gimbal-axis", f"{other.name}={other.profile_path}")]
    return [sys.executable, "-m", "hil.cli", "calibrate", "--profile", str(axis.profile_path),
            "--unit-serial", serial, "--out", str(folder / axis.name), "--store", store_url,
            *siblings, *(("--gimbal-link", link) if link else ()), *options]


def _each_axis(gimbal: GimbalProfile, *, serial: str, folder: Path, store_url: str,
               options: Sequence[str]) -> int:
    """Every axis in order, then the gimbal certificate (:func:`calibrate_gimbal`)."""
    outcomes, codes = [], []
    try:
        with _stops_as_interrupts():
            for index, axis in enumerate(gimbal.axes, start=1):
                print(f"gimbal {serial}: axis {index} of {len(gimbal.axes)}, {axis.name}",
                      flush=True)
                written = _certificate_of(folder, axis, serial)
                before = _stamp(written)
                code, stopped = _calibrate_axis(_axis_argv(
                    gimbal, axis, serial=serial, folder=folder, store_url=store_url,
                    options=options))
                codes.append(INTERRUPTED if stopped else code)
                outcomes.append(_outcome(axis, written, before, code))
                if stopped or code in STOPS_THE_GIMBAL:
                    break
    except KeyboardInterrupt:  # between two axes: the next is not started
        codes.append(INTERRUPTED)
    finally:
        for axis in gimbal.axes[len(outcomes):]:
            outcomes.append(certificate.AxisOutcome(name=axis.name, certificate=None,
                                                    exit_code=certificate.NOT_STARTED))
        _conclude(gimbal, serial=serial, folder=folder, store_url=store_url, axes=outcomes)
    return max(codes, default=0)


def _axes_together(gimbal: GimbalProfile, *, serial: str, folder: Path, store_url: str,
                   options: Sequence[str]) -> int:
    """Both axes at once on one shared simulated gimbal, then the gimbal certificate."""
    from hil.drives.gimbal_link import KEY_VARIABLE
    from hil.drives.shared_gimbal import SharedGimbal

    declared = {(pair[OUTER], pair[INNER]): d.why
                for d in gimbal.beside for pair in [dict(d.protocols)]}
    server = SharedGimbal(outer=OUTER, inner=INNER, declared=declared).start()
    environment = {**os.environ, KEY_VARIABLE: server.key.hex()}
    print(f"gimbal {serial}: {', '.join(a.name for a in gimbal.axes)} at the same time "
          "(one shared gimbal; protocols beside each other where neither disturbs the "
          "other)", flush=True)
    written = {axis.name: _certificate_of(folder, axis, serial) for axis in gimbal.axes}
    before = {name: _stamp(path) for name, path in written.items()}
    codes: dict[str, int] = {}
    try:
        with _stops_as_interrupts():
            codes = _run_at_once(
                {axis.name: _axis_argv(gimbal, axis, serial=serial, folder=folder,
                                       store_url=store_url, options=options,
                                       link=server.address)
                 for axis in gimbal.axes}, environment=environment, ended=server.gone)
    finally:
        server.close()
        together = None if server.error else certificate.together_time(
            server.elapsed_s, {axis: n / server.fs_hz for axis, n in server.busy.items()},
            [(axis, name, start / server.fs_hz, end / server.fs_hz)
             for axis, name, start, end in server.intervals],
            declared={f"{OUTER} {a} beside {INNER} {b}": why
                      for (a, b), why in declared.items()})
        if server.error:
            print(f"gimbal {serial}: the shared gimbal stopped: {server.error}")
        outcomes = [_outcome(axis, written[axis.name], before[axis.name],
                             codes.get(axis.name, INTERRUPTED)) for axis in gimbal.axes]
        _conclude(gimbal, serial=serial, folder=folder, store_url=store_url, axes=outcomes,
                  together=together)
    return max(codes.values(), default=INTERRUPTED)


def _run_at_once(commands: dict[str, list[str]], *, environment: dict[str, str],
                 ended: Callable[[str], None]) -> dict[str, int]:
    """Every command at once, each line of its output shown after its name; a stop is
    passed on to each and waited out (:func:`_calibrate_axis`); their exit codes."""
    processes = {name: subprocess.Popen(argv, env=environment, stdout=subprocess.PIPE,
                                        stderr=subprocess.STDOUT, text=True, bufsize=1)
                 for name, argv in commands.items()}
    width = max(map(len, processes))
    echoes = [threading.Thread(target=_echo, args=(name.ljust(width), process), daemon=True)
              for name, process in processes.items()]
    for echo in echoes:
        echo.start()
    codes: dict[str, int] = {}
    while len(codes) < len(processes):
        try:
            for name, process in processes.items():
                if name not in codes and process.poll() is not None:
                    codes[name] = process.returncode
                    ended(name)
            time.sleep(0.05)
        except KeyboardInterrupt:  # a second stop while they stop is ignored there
            for name, process in processes.items():
                if name not in codes:
                    process.send_signal(signal.SIGINT)
    for echo in echoes:
        echo.join()
    return codes


def _echo(name: str, process: subprocess.Popen[str]) -> None:
    assert process.stdout is not None
    for line in process.stdout:
        print(f"{name} | {line}", end="", flush=True)


def _check_together(gimbal: GimbalProfile, options: Sequence[str]) -> None:
    names = sorted(axis.name for axis in gimbal.axes)
    drive = options[list(options).index("--drive") + 1] if "--drive" in options else "sim"
    if drive != "sim" or names != sorted((OUTER, INNER)):
        raise InputError(f"--together runs an {OUTER} and an {INNER} on one simulated "
                         f"gimbal (--drive sim); this is {', '.join(names)} on --drive {drive}")


def _certificate_of(folder: Path, axis: GimbalAxis, serial: str) -> Path:
    return folder / axis.name / serial / "certificate.json"


def _outcome(axis: GimbalAxis, written: Path, before: int | None,
             code: int) -> certificate.AxisOutcome:
    """Only a certificate this run wrote (a refused axis leaves the last one)."""
    fresh = written if _stamp(written) not in (None, before) else None
    return certificate.AxisOutcome(name=axis.name, certificate=fresh, exit_code=code)


def _conclude(gimbal: GimbalProfile, *, serial: str, folder: Path, store_url: str,
              axes: list[certificate.AxisOutcome],
              together: dict[str, Any] | None = None) -> None:
    """The gimbal certificate, its documents, its record in the store, its verdict."""
    issued = certificate.build(gimbal, serial=serial, folder=folder, axes=axes,
                               together=together)
    json_path, _ = certificate.write(issued, folder)
    for problem in write_documents(json_path):
        print(f"gimbal {serial}: {problem}")
    if store_url != "off":  # the axes' runs are stored by each axis's calibration
        from hil.store.record import record_run

        print(f"gimbal {serial}: {record_run(json_path, out_dir=folder.parent, url=store_url)}")
    each = ", ".join(f"{a['axis']} {a['outcome']}" for a in issued["axes"])
    print(f"gimbal {serial}: {issued['outcome']} ({each}) -> {json_path}")


def _calibrate_axis(argv: list[str]) -> tuple[int, bool]:
    """Run one axis's calibration to its end: its exit code, and whether a stop came. A
    stop (Ctrl-C, or SIGTERM or SIGHUP sent to this process alone) is passed on and waited
    out: the axis's calibration stops the drive, disables it and writes its aborted
    certificate (killing it, or leaving it to run on, would not). The gimbal stops after
    it whatever the axis made of the stop."""
    process = subprocess.Popen(argv)
    stopped = False
    while True:
        try:
            return process.wait(), stopped
        except KeyboardInterrupt:  # a second stop while it stops is ignored there
            stopped = True
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
