"""Sample-rate requirement of a protocol: the reason to skip it where the drive's transport
cannot sample fast enough, instead of running and fitting garbage.

Rule of thumb used by the suite: a protocol whose analysis needs content up to ``f_max``
needs ``OVERSAMPLING × f_max`` samples per second (well above Nyquist's 2×: phase and
amplitude at ``f_max`` are estimated from a handful of samples per period, and a polled
transport samples irregularly).
"""

from __future__ import annotations

import math

from hil.drives.base import DriveInfo

OVERSAMPLING = 4.0  # samples per period of the highest frequency a protocol analyses


def needed_sample_rate_hz(highest_frequency_hz: float) -> float:
    """Sample rate a protocol needs to analyse content up to ``highest_frequency_hz``."""
    if not (math.isfinite(highest_frequency_hz) and highest_frequency_hz > 0):
        raise ValueError(f"highest frequency must be positive, got {highest_frequency_hz!r}")
    return OVERSAMPLING * highest_frequency_hz


def sample_rate_shortfall(
    needed_hz: float, info: DriveInfo, *, protocol: str, why: str
) -> str | None:
    """The skip reason if ``info.max_sample_rate_hz`` is below ``needed_hz``, else None."""
    offered = info.max_sample_rate_hz
    if offered >= needed_hz * (1 - 1e-9):
        return None
    return (
        f"[protocols.{protocol}] needs a sample rate of at least {needed_hz:.4g} Hz ({why}); "
        f"the drive offers {offered:.4g} Hz (drive.info.max_sample_rate_hz, {info.transport}): "
        "not measurable over this link"
    )
