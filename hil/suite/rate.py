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
    """Sample rate a protocol needs to analyse content up to ``highest_frequency_hz``.

    Parameters
    ----------
    highest_frequency_hz : float
        The highest frequency the protocol's analysis uses (Hz).

    Returns
    -------
    float
        ``OVERSAMPLING × highest_frequency_hz`` (Hz).

    Raises
    ------
    ValueError
        ``highest_frequency_hz`` is not a finite positive number.
    """
    if not (math.isfinite(highest_frequency_hz) and highest_frequency_hz > 0):
        raise ValueError(f"highest frequency must be positive, got {highest_frequency_hz!r}")
    return OVERSAMPLING * highest_frequency_hz


def sample_rate_shortfall(
    needed_hz: float, info: DriveInfo, *, protocol: str, why: str
) -> str | None:
    """The skip reason if the drive's link samples slower than a protocol needs.

    Parameters
    ----------
    needed_hz : float
        The sample rate the protocol needs (Hz), e.g. from :func:`needed_sample_rate_hz`.
    info : DriveInfo
        The drive; its ``max_sample_rate_hz`` and ``transport`` are compared and named.
    protocol : str
        The protocol's name, as in the profile's ``[protocols.NAME]``.
    why : str
        What sets ``needed_hz``, for the reason's text.

    Returns
    -------
    str or None
        ``None`` when ``info.max_sample_rate_hz`` reaches ``needed_hz`` (to a relative
        1e-9); otherwise the reason, for the test module to skip with.
    """
    offered = info.max_sample_rate_hz
    if offered >= needed_hz * (1 - 1e-9):
        return None
    return (
        f"[protocols.{protocol}] needs a sample rate of at least {needed_hz:.4g} Hz ({why}); "
        f"the drive offers {offered:.4g} Hz (drive.info.max_sample_rate_hz, {info.transport}): "
        "not measurable over this link"
    )
