"""Start an emulator for a unit profile and hand back the station that reaches it."""

from __future__ import annotations

import dataclasses
import uuid
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from hil.config import builtin_fixture
from hil.drives.canopen_map import ObjectMap
from hil.drives.emulator_faults import CanFaults, ModbusFaults
from hil.drives.odrive.station import OdriveStation
from hil.drives.station import CanOpenStation, ModbusStation, load_station
from hil.errors import ProfileError
from hil.profile import UnitProfile, load_profile
from plant_sim.params import PlantParams

if TYPE_CHECKING:
    from hil.drives.odrive.emulator import OdriveEmulator, OdriveFaults

StationT = TypeVar("StationT", CanOpenStation, ModbusStation)
CANOPEN_STATION = "station_canopen_emulator.toml"
MODBUS_STATION = "station_modbus_emulator.toml"
ODRIVE_STATION = "station_odrive_emulator.toml"


def builtin_station(name: str) -> Path:
    return builtin_fixture(name)


def _plant(profile: UnitProfile, kind: str) -> PlantParams:
    if profile.plant is None:
        raise ProfileError(f"--drive {kind} needs a [plant] table", source=profile.source)
    return profile.plant


def rated_torque_nm(profile: UnitProfile) -> float:
    return float(profile.unit.get("rated_torque_nm", profile.limits.torque_nm))


@contextmanager
def canopen_emulator(
    profile: UnitProfile,
    *,
    seed: int,
    serial: int = 1,
    faults: CanFaults | None = None,
    station_changes: dict[str, Any] | None = None,
    base_station: CanOpenStation | None = None,
    emulated_map: ObjectMap | None = None,
    **emulator_options: Any,
) -> Iterator[tuple[Any, CanOpenStation]]:
    """A running CiA 402 emulator on a private virtual channel, and its station (the
    built-in emulator station's settings, or ``base_station``'s, on that channel).

    The emulator presents itself as the drive model of the station's object map, or of
    ``emulated_map`` when given (a station whose map does not match its drive).

    A station naming a gimbal's axes (``[canopen.axes]``) gets one emulated node per axis
    on that channel: ``profile``'s axis is the node under test, every other axis a node
    emulating the plant of its ``[canopen.emulated_profiles]`` profile, all on one bus
    connection; an azimuth and an elevation node are stepped as one coupled two-axis plant
    (:mod:`hil.drives.cia402.emulator_gimbal`).
    """
    from hil.drives.cia402.emulator import Cia402Emulator
    from hil.drives.cia402.emulator_gimbal import couple, shared_network

    station = base_station or load_station(builtin_station(CANOPEN_STATION))
    assert isinstance(station, CanOpenStation)
    channel = f"gimbal-hil-{uuid.uuid4().hex[:12]}"
    # the emulator's endpoint: a private channel of python-can's virtual bus
    station = dataclasses.replace(station, interface="virtual", channel=channel,
                                  **(station_changes or {})).for_axis(profile.axis)
    with ExitStack() as running:
        network = running.enter_context(shared_network(
            interface=station.interface, channel=channel)) if station.held else None
        held = {name: Cia402Emulator(
            _plant(other, "canopen-emulator"), firmware=other.firmware,
            fs_hz=other.sample_rate_hz, seed=seed + 1000 * (n + 1), channel=channel,
            interface=station.interface, node_id=node_id,
            rated_torque_nm=rated_torque_nm(other), serial_number=serial + n + 1,
            eds_path=station.eds_path, object_map=station.object_map, network=network)
            for n, (name, node_id) in enumerate(station.held.items())
            for other in (_emulated_profile(station, name),)}
        elevation = held.get("elevation")
        emulator = Cia402Emulator(
            _plant(profile, "canopen-emulator"),
            firmware=profile.firmware,
            fs_hz=profile.sample_rate_hz,
            seed=seed,
            channel=channel,
            interface=station.interface,
            node_id=station.node_id,
            rated_torque_nm=rated_torque_nm(profile),
            serial_number=serial,
            faults=faults,
            eds_path=station.eds_path,
            object_map=emulated_map or station.object_map,
            clamp_output_bit=emulator_options.pop("clamp_output_bit", _clamp_bit(station)),
            network=network,
            **emulator_options,
        )
        # an azimuth and an elevation node are one coupled plant; another pair of axes
        # only has the azimuth's J follow the elevation node's position (J_az(el))
        if couple({profile.axis: emulator, **held}, network) is None and elevation is not None:
            emulator.follow_elevation_of(lambda: elevation.plant.position_rad)
        for node in held.values():
            running.enter_context(node)
        emulator.held_nodes = held  # the bus's other emulated nodes, by axis name
        running.enter_context(emulator)
        yield emulator, _with_transducer(station, emulator, running)


def _clamp_bit(station: CanOpenStation | ModbusStation) -> int | None:
    fixture = station.equipment.locked_rotor
    return None if fixture is None else fixture.output_bit


def _with_transducer(station: StationT, emulator: Any, running: ExitStack) -> StationT:
    """``station`` with its torque transducer (if it has one) emulated: an amplifier on
    127.0.0.1 reading the emulated plant's shaft torque."""
    transducer = station.equipment.torque_transducer
    if transducer is None:
        return station
    from hil.drives.transducer_emulator import TransducerEmulator

    amplifier = running.enter_context(TransducerEmulator(
        lambda: emulator.shaft_torque_nm, address=transducer.address))
    emulator.transducer = amplifier
    emulated = dataclasses.replace(transducer, host="127.0.0.1", port=amplifier.port,
                                   scale_nm=1.0, zero_nm=0.0)
    return dataclasses.replace(station, equipment=dataclasses.replace(
        station.equipment, torque_transducer=emulated))


def _emulated_profile(station: CanOpenStation | ModbusStation, axis: str) -> UnitProfile:
    """The profile whose plant the emulator runs at the address of ``axis``."""
    path = station.gimbal.emulated_profiles.get(axis)
    if path is None:
        bus = "canopen" if isinstance(station, CanOpenStation) else "modbus"
        raise ProfileError(f"the emulator needs [{bus}.emulated_profiles] '{axis}' (the "
                           f"profile whose [plant] address {station.gimbal.axes[axis]} "
                           "emulates)", source=station.source)
    return load_profile(path)


@contextmanager
def modbus_emulator(
    profile: UnitProfile,
    *,
    seed: int,
    transport: str = "tcp",
    faults: ModbusFaults | None = None,
    station_changes: dict[str, Any] | None = None,
    base_station: ModbusStation | None = None,
    **emulator_options: Any,
) -> Iterator[tuple[Any, ModbusStation]]:
    """A running Modbus emulator on 127.0.0.1 (TCP, or RTU framing over ``socket://``),
    and its station (the built-in emulator station's settings, or ``base_station``'s,
    at the emulator's port).

    A station naming a gimbal's axes (``[modbus.axes]``) gets one emulated drive per axis
    behind that server, each at its unit id: ``profile``'s axis under test, every other
    axis emulating the plant of its ``[modbus.emulated_profiles]`` profile; the elevation
    drive's position is the azimuth plant's elevation (J_az(el)).
    """
    from hil.drives.modbus.emulator import ModbusEmulator

    station = base_station or load_station(builtin_station(MODBUS_STATION))
    assert isinstance(station, ModbusStation)
    station = station.for_axis(profile.axis)
    held = {
        name: ModbusEmulator(
            _plant(other, "modbus-emulator"), firmware=other.firmware,
            fs_hz=other.sample_rate_hz, seed=seed + 1000 * (n + 1),
            register_map=station.register_map_path, rated_torque_nm=rated_torque_nm(other),
            serial_number=n + 2)
        for n, (name, _) in enumerate(station.held.items())
        for other in (_emulated_profile(station, name),)}
    elevation = held.get("elevation")
    emulator = ModbusEmulator(
        _plant(profile, "modbus-emulator"),
        firmware=profile.firmware,
        fs_hz=profile.sample_rate_hz,
        seed=seed,
        register_map=station.register_map_path,
        rated_torque_nm=rated_torque_nm(profile),
        framing="rtu" if transport == "rtu" else "tcp",
        faults=faults,
        unit_id=station.unit_id if held else None,
        neighbours={station.held[name]: drive for name, drive in held.items()},
        elevation_of=None if elevation is None else lambda: elevation.plant.position_rad,
        clamp_output_bit=emulator_options.pop("clamp_output_bit", _clamp_bit(station)),
        **emulator_options,
    )
    emulator.held_drives = held  # the server's other emulated drives, by axis name
    with ExitStack() as running:
        running.enter_context(emulator)
        changes: dict[str, Any] = {"transport": transport, "port": emulator.port}
        if transport == "rtu":
            changes["serial_port"] = f"socket://127.0.0.1:{emulator.port}"
        station = dataclasses.replace(station, **changes, **(station_changes or {}))
        yield emulator, _with_transducer(station, emulator, running)


@contextmanager
def odrive_emulator(
    profile: UnitProfile,
    *,
    seed: int,
    serial: int = 1,
    faults: OdriveFaults | None = None,
    station_changes: dict[str, Any] | None = None,
    base_station: OdriveStation | None = None,
) -> Iterator[tuple[OdriveEmulator, OdriveStation]]:
    """A running ODrive emulator (CANSimple 0.6) on a private virtual channel, and its
    station (the built-in emulator station's settings, or ``base_station``'s, on that
    channel; the control period that of the profile's plant, K_t its nominal one). The
    emulator paces itself as the station says (``lockstep``: the emulator only)."""
    from hil.drives.odrive.emulator import OdriveEmulator

    plant = _plant(profile, "odrive-emulator")
    station = base_station or load_station(builtin_station(ODRIVE_STATION))
    if not isinstance(station, OdriveStation):
        raise ProfileError("not an odrive station file", source=station.source)
    channel = f"gimbal-hil-{uuid.uuid4().hex[:12]}"
    station = dataclasses.replace(
        station, interface="virtual", channel=channel, can_options={},
        control_period_s=1.0 / profile.sample_rate_hz,
        torque_constant_nm_a=plant.torque_constant_nm_a, **(station_changes or {}))
    with OdriveEmulator(
        plant,
        firmware=profile.firmware,
        fs_hz=profile.sample_rate_hz,
        seed=seed,
        channel=channel,
        node_id=station.node_id,
        pacing=station.pacing,
        feedback_period_ms=station.encoder_period_ms,
        heartbeat_period_ms=station.heartbeat_period_ms,
        error_period_ms=station.error_period_ms,
        serial_number=serial,
        watchdog_timeout_s=station.watchdog_timeout_s,
        faults=faults,
    ) as emulator:
        yield emulator, station
