"""Open a drive by kind: the simulator, an emulator started here, or a real drive from a
station file; every kind is left disabled and closed on leaving."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from hil.drives.base import Drive
from hil.drives.kinds import DriveKind, drive_kind
from hil.errors import InputError, ProfileError
from hil.profile import UnitProfile

if TYPE_CHECKING:
    from hil.beside import Planned
    from hil.drives.gimbal_link import GimbalLink
    from hil.drives.sim import GimbalPartner

#: a gimbal's axes the simulator couples: the outer carries the inner
OUTER_AXIS, INNER_AXIS = "azimuth", "elevation"


@contextmanager
def open_drive(
    kind: str,
    *,
    profile: UnitProfile,
    unit_serial: str,
    station: Path | None = None,
    seed: int = 0,
    gimbal_axes: Mapping[str, UnitProfile] | None = None,
    sim_pace: float | None = None,
    gimbal_link: str | None = None,
    protocols: tuple[Planned, ...] = (),
) -> Iterator[Drive]:
    """Open the drive named by ``kind``; on leaving, the drive is quick-stopped on error
    and always disabled and closed. Emulator kinds start (and stop) their emulator.
    ``gimbal_axes`` (name → profile) are the unit's other axes: the simulator simulates an
    azimuth and an elevation as one coupled gimbal, the other axis held by its drive (the
    emulators take theirs from the station file). ``sim_pace`` keeps the simulator's
    motion to the wall clock (:class:`hil.drives.sim.SimDrive`'s ``pace``).
    ``gimbal_link``: the address of a shared gimbal (:mod:`hil.drives.shared_gimbal`) the
    simulator's axis joins instead of simulating the gimbal itself, telling it
    ``protocols`` (this axis's, in run order) to plan which run beside the other axis's.
    """
    opened = drive_kind(kind)  # an unknown kind: one line naming the known ones
    if opened.opens == "simulator":
        from hil.drives.sim import SimDrive

        if profile.plant is None:
            raise ProfileError(f"--drive {kind} needs a [plant] table", source=profile.source)
        if gimbal_link is not None and sim_pace is not None:
            raise InputError("--sim-pace and --gimbal-link: a shared gimbal keeps its own "
                             "virtual clock (calibrate the gimbal without --together to "
                             "pace it)")
        partner = _gimbal_partner(profile, gimbal_axes or {})
        link = None if gimbal_link is None else _join(gimbal_link, profile, partner,
                                                      seed=seed, protocols=protocols)
        with SimDrive(
            profile.plant,
            firmware=profile.firmware,
            limits=profile.limits,
            fs_hz=profile.sample_rate_hz,
            seed=seed,
            serial=unit_serial,
            partner=partner,
            pace=sim_pace,
            link=link,
        ) as drive:
            yield drive
        return
    with _open_field_drive(
        opened, profile=profile, unit_serial=unit_serial, station=station, seed=seed
    ) as drive:
        yield drive


def _join(address: str, profile: UnitProfile, partner: GimbalPartner | None, *, seed: int,
          protocols: tuple[Planned, ...]) -> GimbalLink:
    """This axis's end of the shared gimbal at ``address`` (connected: both axes are)."""
    from hil.drives.gimbal_link import AxisHello, GimbalLink

    if partner is None:
        raise ProfileError("a shared gimbal needs the other axis (--gimbal-axis NAME=PROFILE) "
                           f"of an azimuth-over-elevation gimbal; this is '{profile.axis}'",
                           source=profile.source)
    assert profile.plant is not None
    return GimbalLink(address, AxisHello(
        axis=profile.axis, plant=profile.plant.with_changes(exact_torque_hold=True),
        firmware=profile.firmware, fs_hz=profile.sample_rate_hz, seed=seed,
        protocols=protocols, holds_other_at_rad=partner.at_rad if partner.name == INNER_AXIS
        else None))


def _gimbal_partner(profile: UnitProfile,
                    others: Mapping[str, UnitProfile]) -> GimbalPartner | None:
    """The other axis of an azimuth-over-elevation gimbal, to simulate with ``profile``'s
    (``None`` for a one-axis unit, or a gimbal of other axes: each simulated alone).
    The held elevation starts where the azimuth's plant parks it; a held azimuth at 0."""
    from hil.drives.sim import GimbalPartner

    pair = {OUTER_AXIS: INNER_AXIS, INNER_AXIS: OUTER_AXIS}
    name = pair.get(profile.axis)
    other = others.get(name) if name is not None else None
    if other is None or other.plant is None:
        return None
    outer = other if name == OUTER_AXIS else profile
    assert outer.plant is not None
    return GimbalPartner(name=other.axis, plant=other.plant, firmware=other.firmware,
                         limits=other.limits,
                         outer=name == OUTER_AXIS,
                         at_rad=outer.plant.elevation_rad if name == INNER_AXIS else 0.0)


@contextmanager
def _open_field_drive(
    kind: DriveKind, *, profile: UnitProfile, unit_serial: str, station: Path | None, seed: int
) -> Iterator[Drive]:
    """The CANopen and Modbus kinds: a real drive from ``station``, or an emulator of
    ``profile.plant`` started here (and stopped on leaving), reached with ``station``'s
    settings when one is given (the built-in emulator station's otherwise)."""
    from hil.drives.station import CanOpenStation, ModbusStation, load_station

    bus = kind.station_kind
    if bus == "odrive":
        with _open_odrive(kind, profile=profile, unit_serial=unit_serial, station=station,
                          seed=seed) as odrive:
            yield odrive
        return
    loaded = None
    if station is not None:  # an emulator takes the file's settings, at its own endpoint
        loaded = load_station(station)
        if not isinstance(loaded, CanOpenStation if bus == "canopen" else ModbusStation):
            raise ProfileError(f"not a {bus} station file", source=str(station))
    if kind.needs_station:
        if loaded is None:
            raise ProfileError(f"--drive {kind.name} needs --station FILE (a station TOML)")
        with _backend(loaded, profile) as drive:
            yield drive
        return
    from hil.drives.emulated import canopen_emulator, modbus_emulator

    serial = int.from_bytes(unit_serial.encode()[-4:].rjust(4, b"\0"), "big")
    if isinstance(loaded, CanOpenStation) or (loaded is None and bus == "canopen"):
        with canopen_emulator(profile, seed=seed, serial=serial,  # noqa: SIM117
                              base_station=loaded) as (_, emulated):
            with _backend(emulated, profile) as drive:
                yield drive
        return
    assert loaded is None or isinstance(loaded, ModbusStation)
    with modbus_emulator(profile, seed=seed, base_station=loaded) as (_, emulated_modbus):  # noqa: SIM117
        with _backend(emulated_modbus, profile) as drive:
            yield drive


@contextmanager
def _backend(station: object, profile: UnitProfile) -> Iterator[Drive]:
    from hil.drives.station import CanOpenStation

    drive: Drive
    if isinstance(station, CanOpenStation):
        from hil.drives.cia402.drive import CanOpenDrive

        drive = CanOpenDrive(station, limits=profile.limits)
    else:
        from hil.drives.modbus.drive import ModbusDrive

        drive = ModbusDrive(station, limits=profile.limits)  # type: ignore[arg-type]
    with drive:
        yield drive


@contextmanager
def _open_odrive(
    kind: DriveKind, *, profile: UnitProfile, unit_serial: str, station: Path | None, seed: int
) -> Iterator[Drive]:
    """An ODrive over CANSimple from ``station``, or an emulated one of ``profile.plant``
    (reached with ``station``'s settings when one is given, at its own virtual channel)."""
    from hil.drives.odrive.drive import OdriveDrive
    from hil.drives.odrive.station import OdriveStation
    from hil.drives.station import load_station

    loaded: OdriveStation | None = None
    if station is not None:
        read = load_station(station)
        if not isinstance(read, OdriveStation):
            raise ProfileError("not an odrive station file (no [odrive] table)",
                               source=str(station))
        loaded = read
    if kind.needs_station:
        if loaded is None:
            raise ProfileError(f"--drive {kind.name} needs --station FILE (a station TOML)")
        with OdriveDrive(loaded, limits=profile.limits) as drive:
            yield drive
        return
    from hil.drives.emulated import odrive_emulator

    serial = int.from_bytes(unit_serial.encode()[-4:].rjust(4, b"\0"), "big")
    with odrive_emulator(profile, seed=seed, serial=serial,  # noqa: SIM117
                         base_station=loaded) as (_, emulated):
        with OdriveDrive(emulated, limits=profile.limits) as drive:
            yield drive
