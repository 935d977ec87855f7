"""Shared test helpers: synthetic recordings with a known model, a test drive's info."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from hil.config import builtin_fixture
from hil.drives.base import Capability, DriveInfo
from hil.motion import Mode
from hil.profile import UnitProfile
from hil.recording import Recording


def drive_info(profile: UnitProfile, fs_hz: float) -> DriveInfo:
    """A test drive with every mode and capability, ``profile``'s limits and ``fs_hz`` as
    its highest sample rate (what a protocol's spec is built against)."""
    return DriveInfo(vendor="test", model="test", firmware_version="0", serial="0",
                     rated_torque_nm=0.5, limits=profile.limits, modes=tuple(Mode),
                     max_sample_rate_hz=fs_hz, capabilities=frozenset(Capability))


def sine_model_recording(
    *,
    inertia: float,
    viscous: float,
    coulomb: float,
    amplitude: float,
    frequency_hz: float,
    periods: int,
    fs_hz: float,
    noise_nm: float = 0.0,
    seed: int = 0,
) -> Recording:
    """Ideal kinematics ω = A·sin(2πft) and torque J·α + B·ω + T_c·sgn(ω) (+ white noise)."""
    # half-sample grid: no sample lands on a zero crossing, so sampled sgn(ω) stays odd
    t = (np.arange(round(periods * fs_hz / frequency_hz)) + 0.5) / fs_hz
    w = 2 * math.pi * frequency_hz
    velocity = amplitude * np.sin(w * t)
    position = amplitude / w * (1 - np.cos(w * t))
    acceleration = amplitude * w * np.cos(w * t)
    torque = inertia * acceleration + viscous * velocity + coulomb * np.sign(velocity)
    torque = (
        torque + np.random.default_rng(seed).normal(0.0, noise_nm, t.size) if noise_nm else torque
    )
    return Recording(
        columns={
            "time_s": t,
            "position_rad": position,
            "velocity_rad_s": velocity,
            "torque_nm": torque,
        },
        source="synthetic",
    )


def subset_profile(directory: Path, *protocols: str,
                   base: str = "demo_gimbal_elevation") -> Path:
    """A demo profile that configures only ``protocols`` and declares only their results:
    a complete calibration of a smaller unit type, for tests that need a quick run that can
    PASS (a ``-k`` subset of the full profile is INCOMPLETE)."""
    from hil.profile import resolve_profile_path
    from hil.suite.catalogue import PROTOCOL_OF

    def keep(match: re.Match[str]) -> str:
        kind, name = match.group(1), match.group(2)
        wanted = name in protocols if kind == "protocols" else PROTOCOL_OF[name] in protocols
        return match.group(0) if wanted else ""

    text = resolve_profile_path(base).read_text(encoding="utf-8")
    text = re.sub(r"^\[(protocols|measurements)\.(\w+)\]\n(?:(?!\[).*\n?)*", keep, text,
                  flags=re.M)
    path = directory / f"{base}-{'-'.join(protocols)}.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


#: the lead a bench sends its Modbus setpoints with when pauses are not the test's subject:
#: 60 ms at 100 Hz bridges the 38–50 ms host stalls seen on CI's runner
BENCH_LEAD_PERIODS = 6


def modbus_bench_station(bench: Path, *, lead_periods: int = BENCH_LEAD_PERIODS) -> Path:
    """The built-in Modbus emulator station, written to ``bench`` with its setpoints sent
    ``lead_periods`` ahead (the built-in file says 3; checked, so a change there is seen)."""
    text = builtin_fixture("station_modbus_emulator.toml").read_text(encoding="utf-8")
    assert "setpoint_lead_periods = 3 " in text
    bench.parent.mkdir(parents=True, exist_ok=True)
    bench.write_text(text.replace("setpoint_lead_periods = 3 ",
                                  f"setpoint_lead_periods = {lead_periods} "), encoding="utf-8")
    return bench
