"""Every protocol of the suite, the results it measures and what it needs from earlier ones,
from each protocol's own module: what a unit profile may configure (``[protocols.NAME]``)
and declare (``[measurements.NAME]``), and in which order. A table that names neither is a
typo, and a protocol listed before one it needs would run without it: both are refused
when the profile is checked, before any motion."""

from __future__ import annotations

import difflib
from collections.abc import Mapping

from hil.drives.base import Capability
from hil.errors import ProfileError
from hil.profile import UnitProfile
from hil.suite import (
    cogging,
    cogging_compensation,
    cross_coupling,
    current_loop,
    gravity_cable,
    inertia_elevation,
    inertia_friction,
    resonance,
    standstill,
    stribeck,
    torque_constant,
    tracking,
    velocity_loop_frf,
    velocity_step,
)
from hil.suite.needs import Need
from hil.suite.protocol import Protocol

#: every protocol of the suite, by name, in the suite's run order
CATALOGUE: Mapping[str, Protocol] = {module.PROTOCOL.name: module.PROTOCOL for module in (
    current_loop, gravity_cable, inertia_friction, stribeck, cogging, torque_constant,
    resonance, inertia_elevation, cross_coupling, velocity_loop_frf, velocity_step, tracking,
    standstill, cogging_compensation)}
#: protocol → the results it measures
PROTOCOLS: Mapping[str, tuple[str, ...]] = {p.name: p.measurements for p in CATALOGUE.values()}
#: protocol → what it takes from earlier protocols (each with its fallback)
NEEDS: Mapping[str, tuple[Need, ...]] = {p.name: p.needs for p in CATALOGUE.values()}
#: protocol → what the station must have to run it (else it is skipped, saying which)
REQUIRES: Mapping[str, tuple[Capability, ...]] = {p.name: p.requires
                                                  for p in CATALOGUE.values()}
#: result → the protocol that measures it
PROTOCOL_OF: Mapping[str, str] = {
    result: protocol for protocol, results in PROTOCOLS.items() for result in results
}


def check_profile(profile: UnitProfile) -> None:
    """Refuse a profile whose protocol or measurement tables the suite does not know, that
    configures no protocol or declares no result, or that declares a result whose protocol
    it does not configure (it could never be measured).

    Raises
    ------
    ProfileError
        One line naming the file and the table (with the nearest known name).
    """
    if not profile.protocols:
        raise ProfileError("configures no protocol: no [protocols.NAME] table (known: "
                           f"{', '.join(PROTOCOLS)})", source=profile.source)
    if not profile.measurements:
        raise ProfileError("declares no result: no [measurements.NAME] table",
                           source=profile.source)
    for name in profile.protocols:
        if name not in PROTOCOLS:
            raise ProfileError(f"[protocols.{name}]: no such protocol{_nearest(name, PROTOCOLS)}",
                               source=profile.source)
    check_order(profile)
    for name in profile.measurements:
        protocol = PROTOCOL_OF.get(name)
        if protocol is None:
            raise ProfileError(f"[measurements.{name}]: no protocol measures "
                               f"'{name}'{_nearest(name, PROTOCOL_OF)}", source=profile.source)
        if protocol not in profile.protocols:
            raise ProfileError(f"[measurements.{name}]: measured by protocol '{protocol}', "
                               f"which the profile does not configure ([protocols.{protocol}])",
                               source=profile.source)


def check_order(profile: UnitProfile) -> None:
    """Refuse a profile that lists a protocol before one it needs: the protocols run in the
    order of the tables, so it would run on its fallback although the profile configures
    what it needs. (Refused, not reordered: the file stays the run order a reader sees.)
    A need on a protocol the profile does not configure is no error: its fallback is used
    and the certificate says so (:func:`hil.suite.needs.note_fallbacks`).

    Raises
    ------
    ProfileError
        One line naming both tables and what is needed.
    """
    order = list(profile.protocols)
    for index, name in enumerate(order):
        for need in NEEDS.get(name, ()):
            if need.protocol in order[index + 1:]:
                raise ProfileError(
                    f"[protocols.{name}] is listed before [protocols.{need.protocol}], whose "
                    f"{need.result} it needs (without it: {need.without}); protocols run in "
                    f"the file's order: move [protocols.{need.protocol}] above it",
                    source=profile.source)


def _nearest(name: str, known: Mapping[str, object]) -> str:
    close = difflib.get_close_matches(name, list(known), n=1)
    return f" (did you mean '{close[0]}'?)" if close else ""
