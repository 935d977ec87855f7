"""Recording I/O per shared/recording-format.md: round trip, refusals, warnings."""

from __future__ import annotations

import gzip
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hil.errors import RecordingError
from hil.recording import Recording, read_recording, write_recording

SHARED = Path(__file__).resolve().parents[2] / "shared"
HEADER = "time_s,position_rad,velocity_rad_s,torque_nm"


def _rows(n: int = 200) -> list[str]:
    return [f"{k * 0.001:.3f},{k * 1e-4:.6f},0.1,{0.01 * np.sin(k):.6f}" for k in range(n)]


def _write(tmp_path: Path, lines: list[str], name: str = "rec.csv") -> Path:
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_round_trip_keeps_columns_metadata_and_values(tmp_path: Path) -> None:
    t = np.arange(500) / 1000.0
    rec = Recording(
        columns={
            "time_s": t,
            "position_rad": np.sin(t),
            "velocity_rad_s": np.cos(t),
            "torque_nm": 0.01 * t,
            "current_a": 0.1 * t,
            "vendor_extra": t,
        },
        metadata={"unit_serial": "GMB-0042", "axis": "elevation"},
    )
    for name in ("r.csv", "r.csv.gz"):
        write_recording(rec, tmp_path / name)
        back = read_recording(tmp_path / name)
        assert back.metadata == {"unit_serial": "GMB-0042", "axis": "elevation"}
        assert set(back.columns) == set(rec.columns)
        np.testing.assert_allclose(back.effort, rec.effort, rtol=1e-8)
        assert back.warnings == ()


def test_unknown_text_columns_are_ignored(tmp_path: Path) -> None:
    lines = [HEADER + ",comment"] + [row + ",ok" for row in _rows()]
    rec = read_recording(_write(tmp_path, lines))
    assert "comment" not in rec.columns
    assert len(rec) == 200


@pytest.mark.parametrize(
    ("mutate", "message", "line", "column"),
    [
        (
            lambda ls: [ls[0].replace(",torque_nm", ",torque"), *ls[1:]],
            "missing required column",
            None,
            "torque_nm",
        ),
        (
            lambda ls: [*ls[:50], "0.049,0,0.1,abc", *ls[51:]],
            "non-numeric value 'abc'",
            51,
            "torque_nm",
        ),
        (lambda ls: [*ls[:10], "0.009,nan,0.1,0", *ls[11:]], "non-finite", 11, "position_rad"),
        (lambda ls: [*ls[:20], "0.005,0,0.1,0", *ls[21:]], "not strictly increasing", 21, "time_s"),
        (lambda ls: ls[:60], "at least 100", None, None),
        (
            lambda ls: [HEADER + ",torque_nm"] + [r + ",0" for r in ls[1:]],
            "duplicate column",
            None,
            "torque_nm",
        ),
        (lambda ls: [HEADER + ",force_n"] + [r + ",0" for r in ls[1:]], "mixes rotary", None, None),
        (lambda ls: [*ls[:30], "0.029,0,0.1", *ls[31:]], "has 3 fields", 31, None),
    ],
)
def test_bad_input_is_refused_with_file_line_and_column(
    tmp_path: Path,
    mutate,
    message: str,
    line: int | None,
    column: str | None,  # type: ignore[no-untyped-def]
) -> None:
    path = _write(tmp_path, mutate([HEADER, *_rows()]))
    with pytest.raises(RecordingError, match=message) as caught:
        read_recording(path)
    assert caught.value.source == str(path)
    assert caught.value.line == line
    assert caught.value.column == column


def test_metadata_lines_shift_reported_line_numbers(tmp_path: Path) -> None:
    lines = ["# unit_serial: X", "# axis: azimuth", HEADER, *_rows()]
    lines[40] = "0.037,0,0.1,oops"
    with pytest.raises(RecordingError) as caught:
        read_recording(_write(tmp_path, lines))
    assert caught.value.line == 41


def test_unreadable_and_corrupt_files(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="cannot read"):
        read_recording(tmp_path / "missing.csv")
    bad = tmp_path / "bad.csv.gz"
    bad.write_bytes(b"not gzip at all")
    with pytest.raises(RecordingError, match="cannot read"):
        read_recording(bad)


def test_warnings_for_gaps_saturation_and_frozen_position(tmp_path: Path) -> None:
    t = np.arange(1000) / 1000.0
    t[500:] += 0.05  # a 50-sample gap
    torque = np.clip(np.sin(20 * t), -0.5, 0.5)  # clipped a large part of the time
    rec = Recording(
        columns={
            "time_s": t,
            "position_rad": np.zeros_like(t),
            "velocity_rad_s": np.zeros_like(t),
            "torque_nm": torque,
        }
    )
    write_recording(rec, tmp_path / "w.csv")
    warnings = " | ".join(read_recording(tmp_path / "w.csv").warnings)
    assert "gap" in warnings
    assert "saturation" in warnings
    assert "never changes" in warnings


def test_linear_axis_uses_linear_columns(tmp_path: Path) -> None:
    lines = ["time_s,position_m,velocity_m_s,force_n", *_rows()]
    rec = read_recording(_write(tmp_path, lines))
    assert rec.axis_kind == "linear"
    assert rec.units["effort"] == "N"
    np.testing.assert_allclose(rec.position[:3], [0.0, 1e-4, 2e-4])


@pytest.mark.skipif(not (SHARED / "recordings").is_dir(), reason="shared data not beside repo")
def test_shared_examples_and_real_data_are_read() -> None:
    for path in sorted((SHARED / "recordings").glob("*.csv.gz")):
        rec = read_recording(path)
        assert len(rec) > 10_000
        assert rec.axis_kind == "rotary"
    emps = read_recording(SHARED / "real-data" / "emps_train.csv.gz")
    assert emps.axis_kind == "linear"
    assert emps.metadata["sample_rate_hz"] == "1000"
    odrive = read_recording(SHARED / "real-data" / "odrive_slow003_nocomp.csv.gz")
    assert np.ptp(np.diff(odrive.time_s)) > 0  # irregular timestamps accepted


def test_gzip_is_deterministic(tmp_path: Path) -> None:
    t = np.arange(200) / 100.0
    rec = Recording(columns={"time_s": t, "position_rad": t, "velocity_rad_s": t, "torque_nm": t})
    assert write_recording(rec, tmp_path / "a.csv.gz") == write_recording(
        rec, tmp_path / "b.csv.gz"
    )
    assert gzip.decompress((tmp_path / "a.csv.gz").read_bytes()).startswith(b"time_s,")


def test_a_long_recording_is_written_the_same_when_half_is_formatted_in_a_child(
        tmp_path: Path) -> None:
    """A single-threaded process formats half of a long recording in a forked child
    (``gimbal-hil simulate``); the file is byte for byte what one process writes."""
    script = (
        "import sys, numpy as np\n"
        "from hil.recording import Recording, write_recording, FORK_ROWS\n"
        "import hil.recording as r\n"
        "n = FORK_ROWS + 12345\n"
        "rng = np.random.default_rng(4)\n"
        "cols = {'time_s': np.arange(n) / 4000.0, 'position_rad': rng.standard_normal(n),\n"
        "        'velocity_rad_s': rng.standard_normal(n) * 1e-5,\n"
        "        'torque_nm': rng.standard_normal(n) * 1e3}\n"
        "rec = Recording(columns=cols, metadata={'drive': 'test'})\n"
        "write_recording(rec, sys.argv[1])\n"
        "r.FORK_ROWS = 10**12\n"
        "write_recording(rec, sys.argv[2])\n"
    )
    done = subprocess.run([sys.executable, "-c", script, str(tmp_path / "forked.csv"),
                           str(tmp_path / "one.csv")], capture_output=True, text=True,
                          check=False, timeout=300)
    assert done.returncode == 0, done.stderr
    forked, one = (tmp_path / "forked.csv").read_bytes(), (tmp_path / "one.csv").read_bytes()
    assert forked == one
    assert forked.count(b"\n") == 200_000 + 12345 + 2  # metadata line, header, rows
