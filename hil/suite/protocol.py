"""A calibration protocol as one object: its name, the results it declares, what it takes
from earlier protocols, what the station must have, and its motion as planned from the
profile (the one sequence its test runs, which the console's "motion left", the
certificate's planned time and the load-time settings check all walk).

Each suite module exports one ``PROTOCOL``; :mod:`hil.suite.catalogue` collects them in run
order. The pytest module in ``protocols/`` runs it, the report draws it (both by name).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

from hil.beside import ALONE, Beside
from hil.details import Details
from hil.drives.base import Capability, DriveInfo
from hil.motion import Excitation
from hil.profile import UnitProfile
from hil.suite.needs import Need

#: where the axis is when a move is built (read then: a generator builds each move after
#: the one before has run)
Position = Callable[[], float]
#: the protocol's motion from the profile, the drive and the axis position
Motion = Callable[[UnitProfile, DriveInfo, Position], Iterable[Excitation]]


@dataclass(frozen=True, slots=True, kw_only=True)
class Protocol:
    """One calibration protocol.

    Attributes
    ----------
    name : str
        Its ``[protocols.NAME]`` table and its pytest module's marker.
    measurements : tuple of str
        The results it measures (``[measurements.NAME]`` tables).
    needs : tuple of Need
        What it takes from earlier protocols, each with what it does without.
    requires : tuple of Capability
        What the station must have (else it is skipped, saying which).
    planned_motion : Motion
        Its excitations as the run will command them, built from the profile alone (a value
        only an earlier protocol measures, such as the feedforward's size, at a stand-in
        that does not change the timing).
    details : type of Details
        The type of what it tells the certificate besides its results
        (:mod:`hil.details`: one writer, one reader).
    beside : Beside
        How it shares a gimbal with the other axis's protocol (:mod:`hil.beside`):
        by default it needs the other axis held, and disturbs it.
    """

    name: str
    measurements: tuple[str, ...]
    needs: tuple[Need, ...]
    requires: tuple[Capability, ...]
    planned_motion: Motion
    details: type[Details]
    beside: Beside = ALONE
