"""Nothing lost (issue 26): history folders that never collide, the store written before
the documents, files written whole or not at all."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hil.profile import load_profile
from hil.recording import Recording, write_recording

KILL_IN_DOCUMENTS = '''
import os

def pytest_configure(config):
    """The process dies (as on SIGKILL or a power cut) while the documents render."""
    import hil.report.documents as documents

    def die(path):
        os._exit(9)

    documents.write_documents = die
'''


def _previous_run(unit: Path, run_id: str, stamp: float) -> None:
    """A finished calibration in ``unit``: its certificate and a recording, written at
    ``stamp`` (seconds since the epoch)."""
    unit.mkdir(parents=True, exist_ok=True)
    (unit / "recordings").mkdir(exist_ok=True)
    (unit / "recordings" / "a.csv.gz").write_bytes(run_id.encode())
    certificate = unit / "certificate.json"
    certificate.write_text(json.dumps({"run": {"id": run_id}}), encoding="utf-8")
    os.utime(certificate, (stamp, stamp))


def test_two_runs_archived_in_the_same_second_keep_both(tmp_path: Path) -> None:
    from hil.calibration import CalibrationRun
    from hil.measurement import MethodBiasMap

    profile = load_profile(None)
    no_bias = MethodBiasMap(source="off", sha256="", entries={})
    unit = tmp_path / "SN-1"
    for run_id in ("11111111-aaaa", "22222222-bbbb", "not a uuid"):
        _previous_run(unit, run_id, stamp=1_700_000_000.0)  # the same second each time
        CalibrationRun(profile=profile, unit_serial="SN-1", out_dir=tmp_path,
                       drive_kind="sim", method_bias=no_bias).archive_previous()
    kept = sorted(unit.glob("history/*/certificate.json"))
    assert sorted(json.loads(p.read_text())["run"]["id"] for p in kept) == \
        ["11111111-aaaa", "22222222-bbbb", "not a uuid"]
    assert sorted((p.parent / "recordings" / "a.csv.gz").read_bytes() for p in kept) == \
        [b"11111111-aaaa", b"22222222-bbbb", b"not a uuid"]
    assert {p.parent.name[:16] for p in kept} == {"20231114T221320Z"}
    assert "20231114T221320Z-11111111" in {p.parent.name for p in kept}  # the run's id


def test_the_store_has_the_run_when_the_documents_are_never_written(tmp_path: Path) -> None:
    (tmp_path / "killdocs.py").write_text(KILL_IN_DOCUMENTS, encoding="utf-8")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(tmp_path), *filter(None, [os.environ.get("PYTHONPATH")])])}
    out, store = tmp_path / "out", tmp_path / "store.sqlite"
    done = subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--drive", "sim", "--unit-serial",
         "DOCS-1", "--out", str(out), "--store", f"sqlite:///{store}", "--",
         "-p", "killdocs", "-k", "current_loop"],
        capture_output=True, text=True, timeout=600, check=False, env=env)
    assert done.returncode == 9, done.stdout[-3000:] + done.stderr[-3000:]  # died there
    certificate = json.loads((out / "DOCS-1" / "certificate.json").read_text("utf-8"))
    assert not (out / "DOCS-1" / "certificate.pdf").exists()

    from hil.store import open_store
    from hil.store.query import history

    opened = open_store(f"sqlite:///{store}")
    try:
        stored = [run.certificate_id for run in history(opened, "DOCS-1")]
    finally:
        opened.close()
    assert stored == [certificate["certificate_id"]]


def _recording(value: float) -> Recording:
    n = 200
    time_s = np.arange(n) / 1000.0
    return Recording(columns={"time_s": time_s, "position_rad": np.full(n, value),
                              "velocity_rad_s": np.zeros(n), "torque_nm": np.zeros(n)})


def test_a_failed_write_leaves_the_old_file_whole(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "rec.csv.gz"
    write_recording(_recording(1.0), path)
    before = path.read_bytes()

    def disk_full(_descriptor: int) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", disk_full)
    with pytest.raises(OSError, match="No space left"):
        write_recording(_recording(2.0), path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.csv.gz"]  # no temporary left


def test_an_atomic_write_replaces_the_file_whole_with_the_usual_mode(tmp_path: Path) -> None:
    from hil.recording import write_atomic

    path = tmp_path / "certificate.json"
    write_atomic(path, b"first")
    write_atomic(path, b"second")
    assert path.read_bytes() == b"second"
    mask = os.umask(0o022)
    os.umask(mask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~mask
    assert sorted(p.name for p in tmp_path.iterdir()) == ["certificate.json"]
