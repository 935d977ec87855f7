"""Drive backends behind one contract (:class:`hil.drives.base.Drive`)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from hil.drives.base import Drive
from hil.errors import ProfileError

if TYPE_CHECKING:  # hil.profile imports hil.drives.base
    from hil.profile import UnitProfile

DRIVE_KINDS = ("sim", "canopen-emulator", "modbus-emulator", "canopen", "modbus")


@contextmanager
def open_drive(
    kind: str,
    *,
    profile: UnitProfile,
    unit_serial: str,
    station: Path | None = None,
    seed: int = 0,
) -> Iterator[Drive]:
    """Open the drive named by ``kind``; on leaving, the drive is quick-stopped on error
    and always disabled and closed. Emulator kinds start (and stop) their emulator.
    """
    if kind == "sim":
        from hil.drives.sim import SimDrive

        if profile.plant is None:
            raise ProfileError("--drive sim needs a [plant] table", source=profile.source)
        with SimDrive(
            profile.plant,
            limits=profile.limits,
            fs_hz=profile.sample_rate_hz,
            seed=seed,
            serial=unit_serial,
        ) as drive:
            yield drive
        return
    raise ProfileError(f"unknown drive kind '{kind}' (known: {', '.join(DRIVE_KINDS)})")
