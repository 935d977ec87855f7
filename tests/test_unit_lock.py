"""One writer per unit folder (issue 26): a calibration holds ``SERIAL/.gimbal-hil.lock``
for its whole run; a second one of the same serial into the same ``--out`` is refused at
once, in one line naming the holder, before any motion."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hil.cli import main, suite_arguments
from hil.errors import InputError

SERIAL = "LOCK-1"
GATE_PLUGIN = '''
import os, time
from pathlib import Path

def pytest_sessionstart(session):
    """Hold the run (and its lock) until the test opens the gate."""
    Path(os.environ["GATE_WAITING"]).write_text(str(os.getpid()))
    deadline = time.monotonic() + 300
    while not Path(os.environ["GATE_OPEN"]).exists() and time.monotonic() < deadline:
        time.sleep(0.05)
'''


def calibrate(out: Path, *extra: str) -> list[str]:
    """``gimbal-hil calibrate`` of SERIAL into ``out`` (one protocol, no store/documents)."""
    return [sys.executable, "-m", "hil.cli", "calibrate", "--drive", "sim", "--unit-serial",
            SERIAL, "--out", str(out), "--", "--store", "off", "--no-documents",
            "-k", "current_loop", *extra]


def test_the_lock_refuses_a_second_holder_and_names_the_first(tmp_path: Path) -> None:
    from hil.calibration import UnitLock

    first = UnitLock.acquire(tmp_path / SERIAL)
    with pytest.raises(InputError) as refused:
        UnitLock.acquire(tmp_path / SERIAL)
    assert f"pid {os.getpid()} on {socket.gethostname()}, started " in str(refused.value)
    assert str(tmp_path / SERIAL) in str(refused.value)
    first.release()
    UnitLock.acquire(tmp_path / SERIAL).release()  # free again


def test_a_calibration_of_a_locked_unit_is_refused_before_motion(tmp_path: Path) -> None:
    from hil.calibration import UnitLock

    unit = tmp_path / SERIAL
    held = UnitLock.acquire(unit)  # another calibration holds the folder
    try:
        started = time.monotonic()
        done = subprocess.run(calibrate(tmp_path), capture_output=True, text=True,
                              timeout=300, check=False)
        (line,) = done.stderr.splitlines()
        assert done.returncode == 2, done.stdout + done.stderr
        assert line.startswith(f"gimbal-hil: error: {unit}: another calibration is writing "
                               "this unit folder (pid ")
        assert f"pid {os.getpid()} on {socket.gethostname()}" in line
        assert time.monotonic() - started < 60
        # plain pytest: its usage error, before collection
        plain = subprocess.run(
            [sys.executable, "-m", "pytest", *suite_arguments(), "--drive", "sim",
             "--unit-serial", SERIAL, "--out", str(tmp_path), "--store", "off"],
            capture_output=True, text=True, timeout=300, check=False)
        assert plain.returncode == pytest.ExitCode.USAGE_ERROR, plain.stdout + plain.stderr
        assert f"pid {os.getpid()} on {socket.gethostname()}" in plain.stderr
    finally:
        held.release()
    assert sorted(p.name for p in unit.iterdir()) == [".gimbal-hil.lock"]  # nothing written


def test_two_calibrations_of_one_unit_at_once_one_is_refused(tmp_path: Path) -> None:
    (tmp_path / "lockgate.py").write_text(GATE_PLUGIN, encoding="utf-8")
    waiting, gate = tmp_path / "waiting", tmp_path / "open"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(tmp_path), *filter(None, [os.environ.get("PYTHONPATH")])]),
        "GATE_WAITING": str(waiting), "GATE_OPEN": str(gate)}
    out = tmp_path / "out"
    first = subprocess.Popen(calibrate(out, "-p", "lockgate"), env=env, text=True,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 300
        while not waiting.exists():  # the first holds the lock (taken before its session)
            assert first.poll() is None, first.communicate()
            assert time.monotonic() < deadline
            time.sleep(0.05)
        second = subprocess.run(calibrate(out), capture_output=True, text=True, timeout=300,
                                check=False)
    finally:
        gate.touch()
        stdout, stderr = first.communicate(timeout=600)
    assert second.returncode == 2, second.stdout + second.stderr
    (line,) = second.stderr.splitlines()
    assert f"(pid {first.pid} on {socket.gethostname()}, started " in line
    unit = out / SERIAL
    assert (unit / "certificate.json").is_file(), stdout[-3000:] + stderr[-3000:]
    assert not (unit / "history").exists()  # one run, not two
    assert main(["verify", str(unit)]) == 0  # every recording as its certificate lists it


def test_another_axis_of_the_serial_is_refused_before_motion(tmp_path: Path) -> None:
    """A folder holding the elevation axis's certificate of GMB-0042: calibrating the
    azimuth axis into it would file that certificate under ``history/`` as an earlier
    azimuth run. Refused in one line before any motion, nothing moved or written."""
    from hil.characterise.processes import run_command

    unit = tmp_path / "units" / "GMB-0042"
    unit.mkdir(parents=True)
    held = unit / "certificate.json"
    held.write_text(json.dumps({"unit": {"serial": "GMB-0042", "axis": "elevation"}}),
                    encoding="utf-8")
    done = run_command(["calibrate", "--drive", "sim", "--profile", "demo_gimbal_azimuth",
                        "--unit-serial", "GMB-0042", "--out", str(tmp_path / "units"),
                        "--store", "off"], timeout_s=300)
    text = done.stdout + done.stderr
    assert done.returncode == 4, text
    assert "Traceback" not in text
    (line,) = [s for s in text.splitlines() if "holds the elevation axis" in s]
    assert f"--out {tmp_path / 'units' / 'azimuth'}" in line
    assert sorted(p.name for p in unit.iterdir()) == [".gimbal-hil.lock", "certificate.json"]
