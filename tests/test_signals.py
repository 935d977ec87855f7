"""Issue 26, item 12: SIGTERM and SIGHUP stop a calibration as SIGINT does (quick stop,
disable, an aborted certificate, never PASS), SIGINT too when the process started with it
ignored (a script's background job), and a CANopen drive whose host stops its
heartbeat stops the axis on its own (0x1016 consumer heartbeat, 0x6007 abort connection)."""

from __future__ import annotations

import json
import os
import re
import signal
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from hil.drives.cia402.drive import CanOpenDrive
from hil.drives.cia402.emulator import HEARTBEAT_ERROR, QUICK_STOP, SWITCH_ON_DISABLED
from hil.drives.emulated import canopen_emulator
from hil.motion import Mode
from hil.profile import load_profile
from tests.calibration_process import RunningCalibration

# the wall clock times its field-bus loops: run alone, not beside other tests (README)
pytestmark = pytest.mark.realtime

# each backend's log lines: a run moving the axis, quick stop, disabled
STATE_LINES = {
    "sim": (r"sim: running", r"sim: quick stop", r"sim: drive disabled"),
    "canopen-emulator": (r"node 5: streaming", r"node 5 quick-stopped", r"node 5 disabled"),
    "modbus-emulator": (r"modbus .*: polling", r"quick-stopped, at rest", r"drive disabled"),
}


def _calibrate_and_signal(tmp_path: Path, kind: str, signum: signal.Signals, *,
                          after_s: float, sigint_ignored: bool = False
                          ) -> tuple[int, str, list[str], dict[str, object]]:
    """Start a calibration (``sigint_ignored``: as a script's background job), send
    ``signum`` ``after_s`` after protocol 2 started a run other than its move to the start;
    its exit code, console output, the log lines written after the signal, the certificate."""
    # the simulator keeps to the wall clock, as a drive does: the stop lands mid-motion
    # (unpaced, it ends the whole run in about as long as a loaded machine may take to
    # send the signal)
    paced = ("--sim-pace", "1") if kind == "sim" else ()
    run = RunningCalibration(tmp_path, ["--drive", kind, "--unit-serial", "SIG-1",
                                        "--out", str(tmp_path / "out")], paced,
                             sigint_ignored=sigint_ignored)
    run.wait_for_console("▶ protocol 2")
    # not its move to the start of the travel: short enough to end within after_s, and the
    # stop then lands between two runs, with no rows to keep (CI, session 27)
    run.wait_for_log(f"{STATE_LINES[kind][0]} (?!move_to_start)", offset=run.log_size(),
                     timeout_s=60)
    time.sleep(after_s)  # the protocol's motion under way
    logged = run.log_size()
    code = run.stop_with(signum)
    with run.log_file.open("rb") as stream:
        stream.seek(logged)
        after = stream.read().decode("utf-8", "replace").splitlines()
    certificate = tmp_path / "out" / "SIG-1" / "certificate.json"
    assert certificate.is_file(), run.console
    return code, run.console, after, json.loads(certificate.read_text(encoding="utf-8"))


@pytest.mark.parametrize(("kind", "signum", "after_s", "sigint_ignored"), [
    ("sim", signal.SIGTERM, 0.3, False),
    ("sim", signal.SIGHUP, 0.3, False),
    ("sim", signal.SIGINT, 0.3, True),  # a background job's: ignored as it started
    ("canopen-emulator", signal.SIGTERM, 0.3, False),
    ("modbus-emulator", signal.SIGTERM, 0.3, False),
])
def test_a_signal_mid_motion_aborts_stops_and_disables(
    tmp_path: Path, kind: str, signum: signal.Signals, after_s: float, sigint_ignored: bool
) -> None:
    code, console, after, cert = _calibrate_and_signal(tmp_path, kind, signum, after_s=after_s,
                                                       sigint_ignored=sigint_ignored)
    assert code != 0, console
    assert "Traceback" not in console, console
    assert cert["aborted"] is True, f"{console}\n" + "\n".join(after[-60:])
    assert cert["outcome"] != "PASS"
    assert "ABORTED" in console
    _, quick, disabled = STATE_LINES[kind]
    states = [line for line in after if re.search(f"{quick}|{disabled}", line)]
    assert states, after
    assert any(re.search(quick, line) for line in states), after  # the motion stopped
    assert re.search(disabled, states[-1]), after  # and the drive was left disabled
    partial = [raw for raw in cert["raw_data"] if not raw["complete"]]
    assert len(partial) == 1, cert["raw_data"]  # the rows moved until the stop, kept
    assert (tmp_path / "out" / "SIG-1" / partial[0]["file"]).is_file()


def _signal_self(signum: int) -> None:
    os.kill(os.getpid(), signum)
    time.sleep(1.0)  # the handler runs at the next bytecode of the main thread


def test_the_handlers_raise_once_and_are_restored_at_the_end() -> None:
    """In-process: SIGTERM raises KeyboardInterrupt, a second one while stopping does not,
    and the handler from before the calibration is back at its end (no calibration runs:
    a second in-process one re-imports the numba kernel's typing registrations)."""
    from hil.calibration_session import _stop_on_signals

    class Config:
        def __init__(self) -> None:
            self.cleanups: list[Callable[[], None]] = []
            self.stash = pytest.Stash()

        def add_cleanup(self, cleanup: Callable[[], None]) -> None:
            self.cleanups.append(cleanup)

    before = signal.getsignal(signal.SIGTERM)
    config = Config()
    _stop_on_signals(config)  # type: ignore[arg-type]
    try:
        with pytest.raises(KeyboardInterrupt, match="SIGTERM"):
            _signal_self(signal.SIGTERM)
        os.kill(os.getpid(), signal.SIGTERM)  # while stopping: ignored
        time.sleep(0.1)
    finally:
        for cleanup in config.cleanups:
            cleanup()
    assert signal.getsignal(signal.SIGTERM) is before


# a pytest plugin for the calibration's process: after protocol 1, a finaliser that is
# running when a SIGTERM arrives (Python prints its KeyboardInterrupt and drops it)
LOSES_THE_INTERRUPT = """
import os, signal


class _Finaliser:
    def __del__(self):
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(100_000):  # the handler runs here, and its interrupt is dropped
            pass


def pytest_runtest_teardown(item, nextitem):
    if "current_loop" in item.nodeid and not os.environ.get("LOST_STOP_SENT"):
        os.environ["LOST_STOP_SENT"] = "1"
        _Finaliser()
        open("interrupt-dropped", "w").close()  # reached: the interrupt did not propagate
"""


def test_a_stop_whose_interrupt_python_drops_still_stops_the_run(tmp_path: Path) -> None:
    """A stop signal landing in a finaliser (Python drops the interrupt its handler raises:
    session 30's one CI failure of the gimbal's stop test, a certificate not aborted, fits
    this): the request is kept, so no later protocol or motion starts, the certificate is
    aborted and the drive ends disabled. Before, the run went on to its end and passed."""
    (tmp_path / "lost_stop.py").write_text(LOSES_THE_INTERRUPT, encoding="utf-8")
    run = RunningCalibration(tmp_path, ["--unit-serial", "SIG-2", "--out",
                                        str(tmp_path / "out")], ("-p", "lost_stop"))
    code = run.wait(600)
    assert (tmp_path / "interrupt-dropped").is_file(), run.console
    assert code != 0, run.console
    certificate = json.loads((tmp_path / "out" / "SIG-2" / "certificate.json").read_text(
        encoding="utf-8"))
    assert certificate["aborted"] is True, run.console
    assert certificate["outcome"] != "PASS"
    log = run.log_file.read_text(encoding="utf-8")
    assert "gravity_cable not started" in run.console, run.console
    assert "sim: running sweep" not in log, log  # protocol 2's motion
    assert re.findall(r"sim: (running|drive disabled)", log)[-1] == "drive disabled", log


def test_a_canopen_drive_stops_when_the_hosts_heartbeat_stops() -> None:
    """The backend produces a heartbeat and configures the drive to consume it (0x1016)
    and quick-stop on its loss (0x6007 = 3); the emulator does, with no SYNC coming (a
    dead host sends none either), and ramps to rest once SYNCs run it again."""
    profile = load_profile()
    changes = {"host_heartbeat_timeout_s": 0.4}
    with canopen_emulator(profile, seed=0, station_changes=changes) as (emulator, station):
        drive = CanOpenDrive(station, limits=profile.limits)
        try:
            assert emulator._raw(0x1016, 1) == (127 << 16 | 400)
            assert emulator._raw(0x6007) == 3
            drive.enable(Mode.VELOCITY)
            link = drive.link
            assert drive.scaling is not None
            link.target = drive.scaling.to_drive(Mode.VELOCITY, 0.1)  # rad/s: stays in travel
            deadline = time.monotonic() + 0.8  # longer than the consumer time: no trip
            while time.monotonic() < deadline:
                link.tick()
            assert emulator.host_lost == 0
            assert emulator.state == "OPERATION ENABLED"
            assert emulator.plant.velocity_rad_s > 0.05
            link.stop_host_heartbeat()  # the host "dies": no heartbeat, no SYNC
            time.sleep(0.8)
            assert emulator.host_lost == 1
            assert emulator.state == QUICK_STOP
            assert HEARTBEAT_ERROR in emulator.emcy_sent
            for _ in range(400):  # SYNCs again: the quick-stop ramp runs to rest
                link.tick()
            assert emulator.state in (QUICK_STOP, SWITCH_ON_DISABLED)
            assert abs(emulator.plant.velocity_rad_s) < 0.05
            assert np.isfinite(emulator.plant.position_rad)
        finally:
            drive.close()
