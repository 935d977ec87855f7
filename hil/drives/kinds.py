"""The drive kinds ``--drive`` accepts, each one object: whether it is simulated, whether
it needs a station file and of which bus, how :mod:`hil.drives.connect` opens it.

Kept import-light (the pytest entry point reads it) and free of the simulator and the
emulators (an import contract): how a kind opens is named here, done in ``connect``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from hil.errors import ProfileError

#: how a kind opens: the built-in simulator, an emulator started here, a real drive
Opener = Literal["simulator", "emulator", "station"]
#: the station file's table a kind reads (``[canopen]``, ``[modbus]``, ``[odrive]``);
#: None: no file
StationKind = Literal["canopen", "modbus", "odrive"]


@dataclass(frozen=True, slots=True, kw_only=True)
class DriveKind:
    """One ``--drive`` kind."""

    name: str
    simulated: bool  # no real unit moves: the certificate says so, no --unit-serial needed
    opens: Opener
    station_kind: StationKind | None  # the bus a --station file must describe

    @property
    def needs_station(self) -> bool:
        """A real drive is reached only through a station file (an emulator may take one)."""
        return self.opens == "station"


KINDS: dict[str, DriveKind] = {
    k.name: k
    for k in (
        DriveKind(name="sim", simulated=True, opens="simulator", station_kind=None),
        DriveKind(name="canopen-emulator", simulated=True, opens="emulator",
                  station_kind="canopen"),
        DriveKind(name="modbus-emulator", simulated=True, opens="emulator",
                  station_kind="modbus"),
        DriveKind(name="canopen", simulated=False, opens="station", station_kind="canopen"),
        DriveKind(name="modbus", simulated=False, opens="station", station_kind="modbus"),
        DriveKind(name="odrive-emulator", simulated=True, opens="emulator",
                  station_kind="odrive"),
        DriveKind(name="odrive", simulated=False, opens="station", station_kind="odrive"),
    )
}
#: the names, in ``--help`` order (argparse's choices)
DRIVE_KINDS: tuple[str, ...] = tuple(KINDS)
#: the simulated kinds' names (need no --unit-serial)
SIMULATED_KINDS: tuple[str, ...] = tuple(k.name for k in KINDS.values() if k.simulated)


def drive_kind(name: str) -> DriveKind:
    """The kind called ``name``.

    Raises
    ------
    ProfileError
        No such kind (the known ones listed).
    """
    kind = KINDS.get(name)
    if kind is None:
        raise ProfileError(f"unknown drive kind '{name}' (known: {', '.join(KINDS)})")
    return kind
