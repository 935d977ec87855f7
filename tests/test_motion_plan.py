"""One motion sequence per protocol, run by its test and summed by the planner (issue 25,
defect 2): over the simulator, each protocol's planned motion time is the motion time its
certificate reports.

Tolerance (per protocol): the plan walks the axis ideally, a velocity run ending at its
start plus the command's integral and a torque run where it began; the simulated axis ends
a protocol up to a few tens of mrad from there (following error, the drift of the torque
and multisine runs), and the next protocol's first move then differs by 2·δ/v. We allow
δ = 50 mrad at the slowest move speed configured, plus two samples of rounding. The
torque-constant protocol's locked angles are also nudged by the cogging protocol's ripple
table, measured after the plan is made: its tolerance adds the most that the nudges the
certificate reports (configured against locked angles) can change its moves.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from hil.characterise.processes import run_command
from hil.drives.connect import open_drive
from hil.profile import load_profile
from hil.suite import torque_constant
from hil.suite.plan import planned_motion_s
from hil.suite.travel import MOVE_SPEED_FRACTION

pytestmark = pytest.mark.slow(seconds=20)

START_ERROR_RAD = 0.05  # how far the real axis may end a protocol from the planned end


def _calibrate(base: str, out: Path) -> dict[str, Any]:
    done = run_command(
        ["calibrate", "--profile", base, "--unit-serial",
         "PLAN-1", "--out", str(out), "--", "--store", "off", "--no-documents"],
        timeout_s=900, cwd=out.parent,
    )
    path = out / "PLAN-1" / "certificate.json"
    assert path.is_file(), done.stdout + done.stderr
    cert: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return cert


def _nudge_s(cert: dict[str, Any], spec: torque_constant.Spec) -> float:
    """The most the locked angles' nudges change the moves between them: each move's
    length changes by at most the nudges of its two ends."""
    per_angle = cert["method"]["details"]["torque_constant"]["per_angle"]
    locked = [float(a["angle_rad"]) for a in per_angle]
    nudges = [abs(a - c) for a, c in zip(locked, spec.angles_rad, strict=True)]
    ends = sum(nudges[i] + (nudges[i - 1] if i else 0.0) for i in range(len(nudges)))
    return 2 * ends / spec.move_speed_rad_s


@pytest.mark.parametrize("base", ["demo_gimbal_elevation", "demo_gimbal_azimuth"])
def test_the_planned_motion_is_the_motion_run(base: str, tmp_path_factory: pytest.TempPathFactory
                                              ) -> None:
    cert = _calibrate(base, tmp_path_factory.mktemp(base) / "out")
    profile = load_profile(base)
    with open_drive("sim", profile=profile, unit_serial="PLAN", station=None, seed=0) as drive:
        info = drive.info
    plan = planned_motion_s(profile, info)
    slowest = min(MOVE_SPEED_FRACTION * info.limits.velocity_rad_s,
                  *(float(t["move_speed_rad_s"]) for t in profile.protocols.values()
                    if "move_speed_rad_s" in t))
    tolerance = 2 * START_ERROR_RAD / slowest + 2 / profile.sample_rate_hz
    ran = {n: p["motion_time_s"] for n, p in cert["method"]["protocols"].items()
           if p["outcome"] != "SKIPPED"}
    assert set(ran) <= set(plan)
    for name, motion_s in ran.items():
        allowed = tolerance
        if name == "torque_constant":
            allowed += _nudge_s(cert, torque_constant.Spec.from_profile(profile, info))
        assert abs(plan[name] - motion_s) <= allowed, (name, plan[name], motion_s, allowed)
