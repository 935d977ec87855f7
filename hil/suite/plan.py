"""The motion each protocol plans: its excitations' commanded time, from the same
sequence the protocol's test runs (its ``PROTOCOL.planned_motion``), each
protocol's moves from where the one before left the axis (the first from the travel's
centre). The console turns it into the time left."""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Iterable

import numpy as np

from hil.drives.base import Capability, DriveInfo
from hil.errors import HilError, ProfileError
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.suite.catalogue import CATALOGUE
from hil.suite.protocol import Position

log = logging.getLogger(__name__)


class _Track:
    """The planned axis position, advanced by each excitation as the drive would be: a
    move ends at its last command, a velocity run at its start plus the command's
    integral, a torque run (sines about a point, a locked rotor) where it began."""

    def __init__(self, at_rad: float) -> None:
        self.at_rad = at_rad

    def position(self) -> float:
        return self.at_rad

    def walk(self, excitations: Iterable[Excitation]) -> list[Excitation]:
        out = []
        for e in excitations:  # a generator builds its next move after the last advance
            out.append(e)
            if e.mode is Mode.POSITION:
                self.at_rad = float(e.command[-1])
            elif e.mode is Mode.VELOCITY:
                self.at_rad += float(np.sum(e.command)) / e.fs_hz
        return out


def acquisition_info(name: str, profile: UnitProfile, info: DriveInfo
                     ) -> tuple[DriveInfo, str | None]:
    """The drive as protocol ``name`` sees it, and why, if not as it is.

    A drive whose highest rate is its own recorder's (:class:`hil.drives.base.Recorder`)
    keeps it for a protocol whose every planned run fits the recorder; a protocol with one
    that does not (too many samples, a torque offset), or that reads the station's shaft
    torque transducer (the host reads it beside the stream, the recorder cannot), is
    planned and run streamed, at the link's rate, so that it completes instead of stopping
    at that run.

    Returns
    -------
    tuple
        The drive info to build the protocol's spec from, and ``None`` or the line that
        says why it streams.
    """
    protocol = CATALOGUE.get(name)
    if info.recorder is None or protocol is None:
        return info, None
    track = _Track((info.limits.travel_min_rad + info.limits.travel_max_rad) / 2)
    try:
        excitations = track.walk(protocol.planned_motion(profile, info, track.position))
    except (HilError, ValueError):
        return info, None  # the protocol states its own error when it builds the spec
    reasons = [r for e in excitations if (r := info.recorder.refuses(e)) is not None]
    if Capability.TORQUE_SENSOR in protocol.requires:
        reasons.insert(0, "it reads the station's shaft torque transducer, which the drive "
                          "recorder does not record")
    if not reasons:
        return info, None
    if Capability.TORQUE_SENSOR not in protocol.requires:
        decimated = _decimated(protocol.planned_motion, profile, info, excitations)
        if decimated is not None:
            return decimated, (f"on the drive recorder at {decimated.max_sample_rate_hz:.4g} Hz "
                               f"({info.max_sample_rate_hz:g} Hz / "
                               f"{round(info.max_sample_rate_hz / decimated.max_sample_rate_hz)}"
                               f"), not at {info.max_sample_rate_hz:g} Hz: {reasons[0]}")
    streamed = info.streamed()
    return streamed, (f"streamed at {streamed.max_sample_rate_hz:g} Hz, not by the drive "
                      f"recorder at {info.max_sample_rate_hz:g} Hz: {reasons[0]}")


def _decimated(planned_motion: Callable[[UnitProfile, DriveInfo, Position],
                                         Iterable[Excitation]],
               profile: UnitProfile, info: DriveInfo, at_top: list[Excitation]
               ) -> DriveInfo | None:
    """The drive at the highest rate ``info.max_sample_rate_hz / n`` above the link's
    stream rate at which every planned run fits its recorder (a recorder samples at its
    control rate divided by a whole number), or ``None``: a run that no such rate makes fit
    (a torque offset the recorder does not play, or too many samples even at the lowest).
    A longer run then keeps the recorder's rate the protocol needs instead of the link's."""
    recorder = info.recorder
    assert recorder is not None
    longest = max(len(e.command) * info.max_sample_rate_hz / e.fs_hz for e in at_top)
    n = max(2, math.ceil(longest / recorder.samples))
    while (rate := info.max_sample_rate_hz / n) > recorder.stream_rate_hz * (1 + 1e-9):
        seen = dataclasses.replace(info, max_sample_rate_hz=rate)
        track = _Track((info.limits.travel_min_rad + info.limits.travel_max_rad) / 2)
        try:
            runs = track.walk(planned_motion(profile, seen, track.position))
        except (HilError, ValueError):
            return None
        refused = [r for e in runs if (r := recorder.refuses(e)) is not None]
        if not refused:
            return seen
        if not any(len(e.command) > recorder.samples for e in runs):
            return None  # not the length: a slower rate does not help
        n += 1
    return None


def planned_motion_s(profile: UnitProfile, info: DriveInfo) -> dict[str, float]:
    """Commanded motion time of each protocol the profile configures, in run order.

    Parameters
    ----------
    profile : UnitProfile
        The unit's profile (its ``[protocols.*]`` tables, in order).
    info : DriveInfo
        The drive (sample rate and limits shape the excitations).

    Returns
    -------
    dict
        Protocol → seconds of commanded motion (one run: a stop rule's repeats are not
        planned); 0 for one this module cannot plan (an unknown protocol, or settings its
        protocol will refuse with an error of its own) and for one the station lacks a
        capability for (it will be skipped).
    """
    track = _Track((info.limits.travel_min_rad + info.limits.travel_max_rad) / 2)
    plan = {}
    for name in profile.protocols:  # each from where the one before left the axis
        protocol = CATALOGUE.get(name)
        runs = protocol is not None and info.lacking(protocol.requires) is None
        seen, _ = acquisition_info(name, profile, info)
        try:
            excitations = track.walk(protocol.planned_motion(profile, seen, track.position)
                                     ) if protocol is not None and runs else []
        except (HilError, ValueError) as exc:
            log.debug("no motion plan for %s: %s", name, exc)
            excitations = []
        plan[name] = sum(e.duration_s for e in excitations)
    return plan


def check_protocol_settings(profile: UnitProfile, info: DriveInfo) -> None:
    """Read every configured protocol's settings and build its motion, as the run will, so
    that a misspelt or impossible setting stops the run before the first motion.

    Raises
    ------
    HilError
        The protocol's own one-line error (file, table and key); a ``ValueError`` of an
        excitation builder becomes a :class:`ProfileError` naming the protocol's table.
    """
    track = _Track((info.limits.travel_min_rad + info.limits.travel_max_rad) / 2)
    for name in profile.protocols:
        protocol = CATALOGUE.get(name)
        if protocol is None:
            continue
        try:
            track.walk(protocol.planned_motion(profile, acquisition_info(name, profile, info)[0],
                                               track.position))
        except ValueError as exc:
            raise ProfileError(f"[protocols.{name}]: {exc}", source=profile.source) from None
