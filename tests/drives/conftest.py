"""Fixtures of the drive-backend tests: the demo profile and short excitations."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.motion import Excitation, Mode
from hil.profile import UnitProfile, load_profile


@pytest.fixture(scope="session")
def profile() -> UnitProfile:
    return load_profile()


def sine(
    amplitude_rad_s: float,
    *,
    fs_hz: float,
    periods: int = 2,
    frequency_hz: float = 2.0,
    name: str = "sine",
) -> Excitation:
    t = np.arange(round(periods * fs_hz / frequency_hz)) / fs_hz
    return Excitation(
        name=name,
        mode=Mode.VELOCITY,
        fs_hz=fs_hz,
        command=amplitude_rad_s * np.sin(2 * math.pi * frequency_hz * t),
    )
