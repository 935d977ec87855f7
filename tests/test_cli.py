"""The gimbal-hil command: simulate, calibrate, clear errors with exit code 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hil.characterise.processes import run_command
from hil.cli import main
from hil.recording import read_recording
from tests.helpers import subset_profile


def test_simulate_builtin_excitation_writes_a_valid_recording(tmp_path: Path) -> None:
    out = tmp_path / "rec.csv.gz"
    assert main(["simulate", "--duration", "10", "--out", str(out)]) == 0
    rec = read_recording(out)
    assert rec.duration_s == pytest.approx(10.0, abs=1e-3)
    assert rec.sample_rate_hz == pytest.approx(4000.0)
    assert np.ptp(rec.position) > 0.1


def test_simulate_a_command_file_resampled_to_the_drive_rate(tmp_path: Path) -> None:
    t = np.arange(0, 3, 0.002)
    command = tmp_path / "cmd.csv"
    rows = [f"{a:.6f},{b:.6f}" for a, b in zip(t, 0.4 * np.sin(2 * np.pi * t), strict=True)]
    command.write_text("time_s,velocity_cmd_rad_s\n" + "\n".join(rows) + "\n", encoding="utf-8")
    out = tmp_path / "rec.csv"
    assert main(["simulate", "--command", str(command), "--out", str(out), "--seed", "4"]) == 0
    rec = read_recording(out)
    assert rec.sample_rate_hz == pytest.approx(4000.0)
    assert rec.velocity_cmd is not None
    assert np.max(np.abs(rec.velocity_cmd)) == pytest.approx(0.4, rel=1e-3)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("time_s,velocity_cmd_rad_s\n" + "0.0,0\n" * 150, "time is not strictly increasing"),
        ("time_s,speed\n" + "".join(f"{k / 100},0\n" for k in range(150)), "exactly one"),
        ("time_s,velocity_cmd_rad_s\n" + "".join(f"{k / 100},9\n" for k in range(150)),
         "exceeds"),
    ],
)
def test_bad_command_files_exit_2_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str, message: str
) -> None:
    command = tmp_path / "cmd.csv"
    command.write_text(content, encoding="utf-8")
    assert main(["simulate", "--command", str(command), "--out", str(tmp_path / "r.csv")]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err
    assert not (tmp_path / "r.csv").exists()


def test_calibrate_runs_the_suite_and_writes_the_certificate(tmp_path: Path) -> None:
    done = run_command(
        ["calibrate", "--drive", "sim", "--unit-serial", "CLI-7", "--out", str(tmp_path),
         "--profile", str(subset_profile(tmp_path / "profiles", "inertia_friction"))],
        timeout_s=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    cert = json.loads((tmp_path / "CLI-7" / "certificate.json").read_text())
    assert cert["outcome"] == "PASS"
    assert "unit CLI-7: PASS" in done.stdout
    assert "(and certificate.txt, certificate.html, certificate.pdf beside it)" in done.stdout


def test_without_documents_the_console_names_only_what_was_written(tmp_path: Path) -> None:
    done = run_command(
        ["calibrate", "--drive", "sim", "--unit-serial", "CLI-8", "--out", str(tmp_path),
         "--profile", str(subset_profile(tmp_path / "profiles", "current_loop")), "--",
         "--no-documents", "--store", "off"],
        timeout_s=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "(and certificate.txt beside it)" in done.stdout
    assert not (tmp_path / "CLI-8" / "certificate.html").exists()


def test_a_reader_that_goes_away_ends_the_command_quietly(tmp_path: Path) -> None:
    """``gimbal-hil results … | head``: the pipe closed early is no internal error."""
    import subprocess
    import sys

    reader = subprocess.Popen(
        [sys.executable, "-c", "import sys; sys.stdin.readline()"], stdin=subprocess.PIPE)
    assert reader.stdin is not None
    command = subprocess.run(
        [sys.executable, "-c", "import sys\nfrom hil.cli import main\n"
         "import hil.cli\nhil.cli._verify = lambda args: [print('x' * 80) for _ in "
         "range(100000)] and 0\nsys.exit(main(['verify', '.']))"],
        stdout=reader.stdin, stderr=subprocess.PIPE, text=True, check=False, cwd=tmp_path,
        timeout=60)
    reader.stdin.close()
    reader.wait(timeout=10)
    assert "internal error" not in command.stderr, command.stderr
    assert "Traceback" not in command.stderr, command.stderr
    assert command.returncode == 141
