"""The operator's console (motion plan, progress line, banner) and the Allure attachments."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from hil.drives.connect import open_drive
from hil.profile import load_profile
from hil.report.console import block_letters, outcome_banner, protocol_start
from hil.suite.plan import planned_motion_s
from hil.suite.travel import MOVE_SPEED_FRACTION, move_excitation
from tests.helpers import subset_profile
from tests.report.runs import Run


def test_block_letters_are_five_even_rows() -> None:
    rows = block_letters("FAIL")
    assert len(rows) == 5
    assert rows[0] == "█████  ███  █████ █"
    assert rows[4] == "█     █   █ █████ █████"


def test_the_banner_never_reads_pass_for_an_error() -> None:
    text = "\n".join(outcome_banner("ERROR", aborted=True))
    assert "NOT COMPLETED" in text
    assert "ABORTED" in text
    assert all(row not in text for row in block_letters("PASS")[1:4])


def test_progress_line_counts_and_scales_by_the_pace() -> None:
    plan = {"a": 10.0, "b": 30.0, "c": 20.0}
    line = protocol_start("b", plan, done_motion_s=10.0, done_wall_s=2.0)
    assert line == ("▶ protocol 2 of 3: b (30.0 s of motion); 50.0 s of motion left, "
                    "about 10 s at this drive's pace")
    assert protocol_start("a", plan, done_motion_s=0.0, done_wall_s=0.0).endswith(
        "60.0 s of motion left")


def test_the_plan_matches_the_motion_the_run_commanded(elevation_run: Run) -> None:
    """Planned from the travel's centre, a protocol's first move may differ from the real
    one (which starts where the last protocol left the axis) by at most a move across the
    whole travel; everything else is the same excitation."""
    profile = load_profile()
    with open_drive("sim", profile=profile, unit_serial="PLAN", station=None, seed=0) as drive:
        plan = planned_motion_s(profile, drive.info)
        limits = drive.info.limits
    across = move_excitation("across", limits.travel_min_rad, limits.travel_max_rad,
                             fs_hz=profile.sample_rate_hz,
                             speed_rad_s=MOVE_SPEED_FRACTION * limits.velocity_rad_s,
                             hold_s=0.0).duration_s
    cert = json.loads((elevation_run.unit_dir / "certificate.json").read_text())
    ran = {n: p["motion_time_s"] for n, p in cert["method"]["protocols"].items()
           if p["outcome"] != "SKIPPED"}
    assert list(plan) == list(ran)
    for name, motion_s in ran.items():
        assert abs(plan[name] - motion_s) <= across, name


def test_allure_gets_each_protocols_plot_and_raw_csv(tmp_path: Path) -> None:
    pytest.importorskip("allure_pytest")
    allure_dir = tmp_path / "allure"
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", "--pyargs",
         "gimbal_hil_protocols.test_inertia_friction", "--out", str(tmp_path / "certs"),
         "--profile", str(subset_profile(tmp_path, "inertia_friction")),
         "--alluredir", str(allure_dir)],
        capture_output=True, text=True, timeout=600, check=False, cwd=tmp_path,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    attached = {}  # attachments made in a test's fixture teardown land in its container
    for container in allure_dir.glob("*-container.json"):
        for step in json.loads(container.read_text()).get("afters", []):
            for a in step.get("attachments", []):
                attached[a["name"]] = allure_dir / a["source"]
    assert "inertia_friction.png" in attached, sorted(attached)
    assert attached["inertia_friction.png"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    csvs = sorted(n for n in attached if n.endswith(".csv"))
    assert csvs == ["inertia_friction__move_to_centre.csv",
                    "inertia_friction__sine_2hz_0.5rad_s.csv",
                    "inertia_friction__sine_2hz_1rad_s.csv"]
    header = attached[csvs[1]].read_text().splitlines()
    assert any(line.startswith("time_s,") for line in header[:40])
