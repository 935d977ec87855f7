"""Sample-rate requirements: a protocol the transport cannot sample fast enough SKIPs with
the rate it needs and the rate the drive offers, before it moves anything."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from hil.drives.base import DriveInfo
from hil.motion import Mode
from hil.profile import UnitProfile, load_profile
from hil.suite import cogging as cogging_suite
from hil.suite import current_loop as current_loop_suite
from hil.suite import resonance as resonance_suite
from hil.suite.rate import (
    OVERSAMPLING,
    needed_sample_rate_hz,
    sample_rate_shortfall,
)

pytest_plugins = ["pytester"]


def _info(profile: UnitProfile, rate_hz: float) -> DriveInfo:
    return DriveInfo(
        vendor="test",
        model="test",
        firmware_version="0",
        serial="0",
        rated_torque_nm=0.5,
        limits=profile.limits,
        modes=(Mode.VELOCITY, Mode.POSITION),
        max_sample_rate_hz=rate_hz,
        transport="modbus tcp 127.0.0.1:1 unit 1",
    )


@pytest.fixture(scope="module")
def elevation() -> UnitProfile:
    return load_profile("demo_gimbal_elevation")


@pytest.fixture(scope="module")
def azimuth() -> UnitProfile:
    return load_profile("demo_gimbal_azimuth")


def test_needed_rate_is_oversampled_highest_frequency() -> None:
    assert needed_sample_rate_hz(150.0) == pytest.approx(OVERSAMPLING * 150.0)
    assert OVERSAMPLING >= 4.0  # well above Nyquist, not at it
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="positive"):
            needed_sample_rate_hz(bad)


def test_too_slow_a_drive_skips_naming_both_rates(elevation: UnitProfile) -> None:
    slow = _info(elevation, 200.0)
    reason = sample_rate_shortfall(600.0, slow, protocol="current_loop", why="4 × 150 Hz")
    assert reason is not None
    assert "[protocols.current_loop]" in reason
    assert "600 Hz" in reason
    assert "200 Hz" in reason
    assert "4 × 150 Hz" in reason
    assert "modbus tcp" in reason


def test_fast_enough_a_drive_runs(elevation: UnitProfile) -> None:
    assert sample_rate_shortfall(600.0, _info(elevation, 600.0), protocol="x", why="y") is None
    assert sample_rate_shortfall(600.0, _info(elevation, 1000.0), protocol="x", why="y") is None
    assert sample_rate_shortfall(600.0, _info(elevation, 599.0), protocol="x", why="y")


def test_protocol_needs_follow_their_settings(elevation: UnitProfile, azimuth: UnitProfile) -> None:
    fast = _info(elevation, 4000.0)
    current = current_loop_suite.Spec.from_profile(elevation, fast)
    assert current.needed_sample_rate_hz == pytest.approx(4 * 150.0)  # frequencies up to 150
    cogging = cogging_suite.Spec.from_profile(elevation, fast)
    # the gravity sweep's passes: order 200 at 0.4 rad/s passes at 200 · 0.4 / 2π = 12.7 Hz;
    # but 4000 samples over a 2.6 rad pass at 0.4 rad/s need more
    assert cogging.needed_sample_rate_hz == pytest.approx(4000 / (2.6 / 0.4))
    assert cogging.needed_sample_rate_hz > 4 * 200 * 0.4 / (2 * math.pi)
    resonance = resonance_suite.spec_from_profile(azimuth, _info(azimuth, 4000.0))
    assert resonance.needed_sample_rate_hz == pytest.approx(4 * 300.0)  # band up to 300 Hz
    # the needs do not depend on the rate a drive offers (no circular planning)
    slow = current_loop_suite.Spec.from_profile(
        elevation, dataclasses.replace(fast, max_sample_rate_hz=100.0)
    )
    assert slow.needed_sample_rate_hz == current.needed_sample_rate_hz


def test_current_loop_skips_over_modbus(pytester: pytest.Pytester, tmp_path: Path) -> None:
    """End to end over the Modbus emulator (real pymodbus on loopback): the link polls at a
    few hundred Hz at most, current_loop needs 600 Hz: SKIPPED with both rates, not an error,
    and the certificate says so."""
    out = tmp_path / "certs"
    result = pytester.runpytest_inprocess(
        "--pyargs",
        "gimbal_hil_protocols.test_current_loop",
        "-p",
        "no:cacheprovider",
        "-rs",
        "--drive",
        "modbus-emulator",
        "--unit-serial",
        "RATE-1",
        "--out",
        str(out),
    )
    outcomes = result.parseoutcomes()
    assert outcomes.get("skipped") == 1, result.stdout.str()
    assert not outcomes.get("failed")
    assert not outcomes.get("errors")
    text = result.stdout.str()
    assert "needs a sample rate of at least 600 Hz" in text
    assert "the drive offers" in text
