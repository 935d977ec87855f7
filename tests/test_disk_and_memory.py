"""Issue 26, items 9 and 15: a full disk and sizes nothing bounded.

A calibration checks the free space of --out before the first motion (the planned samples'
recordings and the documents, with a margin) and refuses in one line; a write that fails
(ENOSPC, EROFS) stops the run at once, in one line, the drive disabled, nothing
half-written. Memory is planned from the inputs: a profile whose motion exceeds the
budget (GIMBAL_HIL_MEMORY_BUDGET_MB) is refused at load, and ``diagnose`` refuses a
recording too long for it (a gzip bomb too) before reading it whole. The failures are
injected by ``-p`` plugins in subprocesses (tests run as root: chmod stops nothing)."""

from __future__ import annotations

import gzip
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import subset_profile

PLUGIN_FULL_DISK = '''
import shutil
from collections import namedtuple

_usage = namedtuple("usage", "total used free")
shutil.disk_usage = lambda path: _usage(10**12, 10**12 - 2_000_000, 2_000_000)
'''

PLUGIN_FAILING_WRITES = '''
import errno, os
import hil.calibration, hil.certificate.build, hil.recording, hil.report.documents
from hil.drives.sim import SimDrive

MARKER = os.environ["MARKER_FILE"]
ERRNO = getattr(errno, os.environ["FAIL_ERRNO"])
_original = hil.recording.write_atomic

def _note(text):
    with open(MARKER, "a", encoding="utf-8") as stream:
        stream.write(text + "\\n")

def write_atomic(path, payload):  # the disk fails once something is written
    _note(f"write {path}")
    raise OSError(ERRNO, os.strerror(ERRNO), str(path))

for module in (hil.recording, hil.calibration, hil.certificate.build, hil.report.documents):
    module.write_atomic = write_atomic

_run, _disable = SimDrive.run, SimDrive.disable

def run(self, excitation):
    _note(f"run {excitation.name}")
    return _run(self, excitation)

def disable(self):
    _note("disable")
    return _disable(self)

SimDrive.run, SimDrive.disable = run, disable
'''


def _calibrate(tmp_path: Path, profile: Path, *options: str,
               env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "hil.cli", "calibrate", "--drive", "sim", "--profile",
               str(profile), "--unit-serial", "DISK-1", "--out", str(tmp_path / "out"), "--",
               "--store", "off", "--no-documents", "-p", "no:cacheprovider", *options]
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(tmp_path / "plugins"), os.environ.get("PYTHONPATH", "")]), **(env or {})}
    return subprocess.run(command, capture_output=True, text=True, env=environment,
                          cwd=tmp_path, timeout=600, check=False)


def _plugin(tmp_path: Path, name: str, text: str) -> str:
    folder = tmp_path / "plugins"
    folder.mkdir(exist_ok=True)
    (folder / f"{name}.py").write_text(text, encoding="utf-8")
    return name


def test_too_little_free_space_is_refused_before_motion(tmp_path: Path) -> None:
    profile = subset_profile(tmp_path / "profiles", "current_loop")
    done = _calibrate(tmp_path, profile, "-p", _plugin(tmp_path, "full_disk", PLUGIN_FULL_DISK))
    console = done.stdout + done.stderr
    assert done.returncode == 4, console
    assert "Traceback" not in console, console
    refusal = [line for line in console.splitlines() if "bytes free" in line]
    assert len(refusal) == 1, console
    assert str(tmp_path / "out") in refusal[0]
    assert "2,000,000 bytes free" in refusal[0]
    assert re.search(r"needs about [\d,]+ bytes", refusal[0])
    assert not (tmp_path / "out" / "DISK-1" / "recordings").exists()  # nothing moved


@pytest.mark.parametrize("error", ["ENOSPC", "EROFS"])
def test_a_failed_write_stops_the_run_at_once_in_one_line(tmp_path: Path, error: str) -> None:
    profile = subset_profile(tmp_path / "profiles", "current_loop", "inertia_friction")
    marker = tmp_path / "marker.txt"
    done = _calibrate(tmp_path, profile, "-p", _plugin(tmp_path, "bad_disk",
                                                       PLUGIN_FAILING_WRITES),
                      env={"MARKER_FILE": str(marker), "FAIL_ERRNO": error})
    console = done.stdout + done.stderr
    assert done.returncode != 0, console
    assert "Traceback" not in console, console
    assert "INTERNALERROR" not in console, console
    said = os.strerror(getattr(__import__("errno"), error))
    lines = [line for line in console.splitlines() if "cannot write" in line and said in line]
    assert lines, console
    assert all(len(line) < 400 for line in lines)
    events = marker.read_text(encoding="utf-8").splitlines()
    runs = [e for e in events if e.startswith("run ")]
    assert len(runs) == 1, events  # no motion after the first failed write
    states = [e for e in events if e.startswith("run ") or e == "disable"]
    assert states[-1] == "disable", events  # and the drive left disabled
    written = [p for p in (tmp_path / "out").rglob("*") if p.is_file()]
    assert not [p for p in written if p.name.endswith(".tmp") or (p.stat().st_size == 0
                and p.name != ".gimbal-hil.lock")], written


def test_a_profile_beyond_the_memory_budget_is_refused_at_load(tmp_path: Path) -> None:
    """100 kHz (plausible) with the gravity sweep (20 s): 2 M samples in one protocol."""
    profile = subset_profile(tmp_path / "profiles", "gravity_cable")
    text = profile.read_text(encoding="utf-8")
    profile.write_text(re.sub(r"(?m)^sample_rate_hz = .*$", "sample_rate_hz = 100000.0",
                              text), encoding="utf-8")
    done = _calibrate(tmp_path, profile, env={"GIMBAL_HIL_MEMORY_BUDGET_MB": "1024"})
    console = done.stdout + done.stderr
    assert done.returncode == 4, console
    assert "Traceback" not in console, console
    refusal = [line for line in console.splitlines() if "MiB of memory" in line]
    assert len(refusal) == 1, console
    assert "gravity_cable" in refusal[0]
    assert "GIMBAL_HIL_MEMORY_BUDGET_MB=1024" in refusal[0]
    assert not (tmp_path / "out" / "DISK-1" / "recordings").exists()


def test_a_profile_whose_excitations_outgrow_the_budget_is_refused(tmp_path: Path) -> None:
    """200,000 Stribeck speeds (23 GB before): building the motion stops at the budget."""
    profile = subset_profile(tmp_path / "profiles", "stribeck")
    speeds = ", ".join(f"{0.2 - 1e-6 * i:.7f}" for i in range(200_000))
    text = re.sub(r"(?m)^speeds_rad_s = .*$", f"speeds_rad_s = [{speeds}]",
                  profile.read_text(encoding="utf-8"))
    profile.write_text(text, encoding="utf-8")
    done = _calibrate(tmp_path, profile, env={"GIMBAL_HIL_MEMORY_BUDGET_MB": "512"})
    console = done.stdout + done.stderr
    assert done.returncode == 4, console
    assert "Traceback" not in console, console
    assert len([line for line in console.splitlines() if line.startswith("ERROR")]) == 1


def _diagnose(tmp_path: Path, recording: Path, budget_mb: str) -> tuple[int, str, float]:
    """``gimbal-hil diagnose`` in a subprocess: exit code, stderr, peak resident MiB."""
    # VmHWM, the peak of this program's own memory: ru_maxrss survives exec and would carry
    # the high-water mark of the process that forked it (the test run's, 800 MB in CI)
    code = ("import re, sys; from hil.cli import main\n"
            "code = main(sys.argv[1:])\n"
            "status = open('/proc/self/status').read()\n"
            "print('MAXRSS_KB', re.search(r'VmHWM:\\s+(\\d+)', status).group(1),"
            " file=sys.stderr)\nsys.exit(code)\n")
    done = subprocess.run([sys.executable, "-c", code, "diagnose", str(recording), "--json",
                           str(tmp_path / "out.json")], capture_output=True, text=True,
                          env={**os.environ, "GIMBAL_HIL_MEMORY_BUDGET_MB": budget_mb},
                          cwd=tmp_path, timeout=600, check=False)
    found = re.search(r"MAXRSS_KB (\d+)", done.stderr)
    assert found, done.stderr
    other = [line for line in done.stderr.splitlines() if not line.startswith("MAXRSS_KB")]
    return done.returncode, "\n".join(other), int(found.group(1)) / 1024


def test_a_million_row_recording_is_refused_before_it_is_read_whole(tmp_path: Path) -> None:
    rows = 1_000_000
    time_s = np.arange(rows) / 4000.0
    velocity = 0.5 * np.sin(2 * np.pi * 1.3 * time_s)
    table = np.column_stack([time_s, np.cumsum(velocity) / 4000.0, velocity,
                             0.01 * velocity + 0.002 * np.sign(velocity)])
    path = tmp_path / "big.csv"
    with path.open("w", encoding="utf-8") as stream:
        stream.write("time_s,position_rad,velocity_rad_s,torque_nm\n")
        np.savetxt(stream, table, fmt="%.9g", delimiter=",")
    code, stderr, peak_mib = _diagnose(tmp_path, path, "2048")
    assert code == 2, stderr
    assert "Traceback" not in stderr
    assert len(stderr.splitlines()) == 1, stderr
    assert "not read further" in stderr
    assert "big.csv" in stderr
    # refused after ~260 k rows of text at most: far below the 2 GiB budget
    assert peak_mib < 600, peak_mib


def test_a_gzip_bomb_is_refused_without_being_decompressed(tmp_path: Path) -> None:
    path = tmp_path / "bomb.csv.gz"
    block = b"0" * (1 << 20)
    with gzip.open(path, "wb", compresslevel=9) as stream:
        for _ in range(200):  # 200 MiB of zeros in ~200 kB
            stream.write(block)
    assert path.stat().st_size < 1_000_000
    code, stderr, peak_mib = _diagnose(tmp_path, path, "64")
    assert code == 2, stderr
    assert "Traceback" not in stderr
    assert len(stderr.splitlines()) == 1, stderr
    assert "bytes of text" in stderr
    assert "not read further" in stderr
    assert peak_mib < 400, peak_mib  # reading it whole holds it three times over
