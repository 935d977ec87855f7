"""Station files (TOML): how this test station reaches its drive.

A *unit profile* describes the unit under test; a *station* describes the bench: which
CAN interface or Modbus link, which node, which object dictionary or register map, and the
scaling between drive units and SI. ``--drive canopen --station FILE`` and
``--drive modbus --station FILE`` read one; the emulator kinds build one in memory.

Paths inside a station file (``eds``, ``register_map``) are relative to the file; a bare
file name that does not exist there is looked up in the built-in ``fixtures/``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from hil.config import ConfigTable, builtin_fixture, read_toml
from hil.drives.canopen_map import GENERIC_MAP, ObjectMap, load_object_map
from hil.drives.equipment import Equipment, read_equipment
from hil.drives.odrive.station import OdriveStation, read_odrive
from hil.errors import ProfileError

SYNC_PACINGS = ("realtime", "lockstep")
# who sends the SYNC: the host from its loop, python-can's periodic send (the kernel's
# broadcast manager on socketcan, else python-can's own thread), or the drive itself
# (CiA 301 0x1005 bit 30); the last two are observed by the host
SYNC_PRODUCERS = ("host", "periodic", "node")
ACQUISITIONS = ("stream", "recorder", "auto")
TORQUE_SAMPLES = ("auto", "mean", "instantaneous")


@dataclass(frozen=True, slots=True, kw_only=True)
class HoldSettings:
    """How the station moves and holds a gimbal's other axes (``[canopen.hold]``,
    ``[modbus.hold]``): each is a drive on the same bus under its own position control
    (CiA 402 profile position; a Modbus map's position mode), moved between the runs of
    the axis under test and holding its angle during them.

    ``speed_rad_s`` and ``accel_rad_s2`` (the move's profile: 0x6081, 0x6083/0x6084 on
    CANopen; the host's setpoints on Modbus), ``window_rad`` (standing within it is
    "reached"), ``settle_s`` (waited after that, the axis under test still),
    ``timeout_s`` (beyond the move's own time: not reached is an error naming the axis),
    ``at_rad`` (the angle each held axis is moved to at bring-up, by axis name; an axis
    not named is held where it stands)."""

    speed_rad_s: float = 0.5
    accel_rad_s2: float = 2.0
    window_rad: float = 0.002
    settle_s: float = 0.2
    timeout_s: float = 5.0
    at_rad: Mapping[str, float] = field(default_factory=dict)


@dataclass(frozen=True, slots=True, kw_only=True)
class GimbalBus:
    """A gimbal's drives on one bus (``[BUS.axes]``: axis name = node or unit id): the
    axis under test is the station's own address, every other axis is ``held`` (moved and
    held by its own drive, ``hold``). ``emulated_profiles`` (``[BUS.emulated_profiles]``)
    is read by the emulator kinds only: the profile whose ``[plant]`` each axis emulates."""

    axes: Mapping[str, int] = field(default_factory=dict)
    held: Mapping[str, int] = field(default_factory=dict)
    hold: HoldSettings = field(default_factory=HoldSettings)
    emulated_profiles: Mapping[str, Path] = field(default_factory=dict)

    def under_test(self, axis: str, *, source: str, table: str) -> tuple[int, dict[str, int]]:
        """The address of ``axis`` and the held axes' addresses, by name.

        Raises
        ------
        ProfileError
            ``axis`` has no address among :attr:`axes`.
        """
        if axis not in self.axes:
            raise ProfileError(f"{table} has no address for the profile's axis '{axis}' "
                               f"(it names {', '.join(sorted(self.axes))})", source=source)
        return self.axes[axis], {n: a for n, a in self.axes.items() if n != axis}


@dataclass(frozen=True, slots=True, kw_only=True)
class CanOpenStation:
    """A CiA 402 drive on a CAN bus reached through python-can.

    ``sync_pacing`` is ``"realtime"`` for a real bus (SYNC every ``sync_period_s`` of
    wall-clock time) or ``"lockstep"`` for a drive whose clock *is* the SYNC (an emulator
    or a drive in a SYNC-stepped simulation mode): the next SYNC goes out as soon as the
    previous one was answered. Never use lockstep on a real axis. ``sync_producer``: who
    sends the SYNC in realtime pacing: ``"host"`` (its loop's sleeps), ``"periodic"``
    (python-can's periodic send: the kernel's broadcast manager on socketcan, else
    python-can's own thread) or ``"node"`` (the drive under test, 0x1005 bit 30, at its
    0x1006); under the last two the host counts the SYNCs it sees. ``max_sync_interval_sd_s``:
    a streamed run whose SYNC intervals spread more is refused, naming the figure.

    ``torque_sample``: which torque a streamed row carries. ``"auto"`` (default): the torque
    averaged over the SYNC period (the object map's ``torque_mean``) when the drive offers
    it, else 0x6077; ``"mean"`` requires it; ``"instantaneous"`` always 0x6077.
    ``control_period_s``: the drive's control-loop period, for a drive that does not report
    it (the object map's ``control_period``); it goes into each recording's metadata.

    A dead host stops the axis: the backend produces its own heartbeat (node
    ``host_node_id``, every ``heartbeat_period_s``) and sets the drive's consumer heartbeat
    time (0x1016) to ``host_heartbeat_timeout_s`` and its abort connection option code
    (0x6007) to ``abort_connection_option_code`` (3: quick stop) at bring-up.
    """

    source: str
    interface: str
    channel: str
    bitrate: int
    node_id: int
    eds_path: Path
    sync_period_s: float = 0.001
    sync_pacing: str = "realtime"
    sync_producer: str = "host"
    max_sync_interval_sd_s: float | None = None  # a streamed run whose SYNCs spread more: refused
    max_bus_load: float = 0.6
    sdo_timeout_s: float = 0.5
    pdo_timeout_s: float = 0.1
    heartbeat_period_s: float = 0.1
    heartbeat_timeout_s: float = 1.0
    state_timeout_s: float = 1.0
    acquisition: str = "stream"
    lost_sample_fraction: float = 0.02
    torque_sample: str = "auto"
    control_period_s: float | None = None
    rated_torque_nm: float | None = None
    rated_current_a: float | None = None
    counts_per_rev: int | None = None
    velocity_units_per_rad_s: float | None = None
    quick_stop_option_code: int = 2
    quick_stop_decel_rad_s2: float = 20.0
    host_node_id: int = 127
    host_heartbeat_timeout_s: float = 1.0
    abort_connection_option_code: int = 3  # 0x6007: 1 fault, 2 disable voltage, 3 quick stop
    can_options: Mapping[str, Any] = field(default_factory=dict)
    gimbal: GimbalBus = field(default_factory=GimbalBus)  # [canopen.axes], [canopen.hold]
    object_map: ObjectMap = field(default_factory=lambda: load_object_map(GENERIC_MAP))
    equipment: Equipment = field(default_factory=Equipment)  # [torque_transducer], ...

    @property
    def held(self) -> Mapping[str, int]:
        return self.gimbal.held

    def for_axis(self, axis: str) -> CanOpenStation:
        """This station as the calibration of ``axis`` uses it: its node that of ``axis``,
        the other axes held (:func:`axis_under_test`)."""
        found = axis_under_test(self, axis)
        return self if found is None else replace(self, node_id=found[0], gimbal=found[1])


@dataclass(frozen=True, slots=True, kw_only=True)
class ModbusStation:
    """A drive reached over Modbus TCP, or Modbus RTU on a serial port or pyserial URL.

    ``torque_sample``: which torque a row carries. ``"auto"`` (default): the register map's
    ``torque_mean`` (the mean since the previous read, i.e. over the row's own period) when
    the map declares it, else the instantaneous ``torque``; ``"mean"`` requires it;
    ``"instantaneous"`` always ``torque``.

    ``setpoint_lead_periods``: with the map's ``setpoint_interpolation_time``, each setpoint
    is the command that many sample periods ahead, approached by the drive's ramp over them
    (no delay at low frequency), and a host late by less than the lead leaves no hold in it
    (a hold is a jerk the 100 Hz rows cannot resolve: J up to −5.5 % at load average 7–10
    with a one-period ramp). A step is spread over the lead.
    """

    source: str
    transport: str  # "tcp" or "rtu"
    register_map_path: Path
    host: str = "127.0.0.1"
    port: int = 502
    serial_port: str = ""  # "/dev/ttyUSB0", "socket://127.0.0.1:5020", "rfc2217://..."
    baudrate: int = 115200
    parity: str = "N"
    stopbits: int = 1
    unit_id: int = 1
    timeout_s: float = 0.5
    max_poll_rate_hz: float = 1000.0
    watchdog_s: float = 0.5
    torque_sample: str = "auto"
    setpoint_lead_periods: int = 3
    acquisition: str = "stream"  # "auto"/"recorder": the map's drive recorder above the poll
    gimbal: GimbalBus = field(default_factory=GimbalBus)  # [modbus.axes], [modbus.hold]
    equipment: Equipment = field(default_factory=Equipment)  # [torque_transducer], ...

    @property
    def held(self) -> Mapping[str, int]:
        return self.gimbal.held

    def for_axis(self, axis: str) -> ModbusStation:
        """This station as the calibration of ``axis`` uses it: its unit id that of
        ``axis``, the other axes held (:func:`axis_under_test`)."""
        found = axis_under_test(self, axis)
        return self if found is None else replace(self, unit_id=found[0], gimbal=found[1])


Station = CanOpenStation | ModbusStation | OdriveStation


def axis_under_test(station: CanOpenStation | ModbusStation, axis: str
                    ) -> tuple[int, GimbalBus] | None:
    """The bus address of ``axis`` and the gimbal part with every other axis held;
    ``None`` for a station without axes (one axis on the bus).

    Raises
    ------
    ProfileError
        The station names axes and ``axis`` is not one of them.
    """
    gimbal = station.gimbal
    if not gimbal.axes:
        return None
    bus = "canopen" if isinstance(station, CanOpenStation) else "modbus"
    own, held = gimbal.under_test(axis, source=station.source, table=f"[{bus}.axes]")
    return own, replace(gimbal, held=held)


@dataclass(frozen=True, slots=True, kw_only=True)
class StationIdentity:
    """The optional ``[station]`` table: which bench this is (``id``), the results store
    its runs go to (``store``, a database URL) and whether it calibrates reference (golden)
    units (``reference``). Any drive kind reads it, the simulator too.

    The certificate's ISO/IEC 17025 7.8 fields come from it too: the laboratory
    (``laboratory``, ``laboratory_address``), the ``customer``, who authorises the
    certificates (``authorised_by``; absent: each says "not authorised") and the
    environmental conditions the bench declares (``temperature_c``, ``humidity_pct``,
    ``conditions``: a free-text note, e.g. "air-conditioned, 23 ± 2 °C").
    """

    station_id: str | None = None
    store: str | None = None
    reference: bool = False
    laboratory: str | None = None
    laboratory_address: str | None = None
    customer: str | None = None
    authorised_by: str | None = None
    temperature_c: float | None = None
    humidity_pct: float | None = None
    conditions: str | None = None


def load_station_identity(path: str | Path) -> StationIdentity:
    """Read only the ``[station]`` table of a station file (absent: all defaults).

    Raises
    ------
    ProfileError
        The file is missing or the table holds an unknown key or a wrong type.
    """
    path = Path(path)
    if not path.is_file():
        raise ProfileError("station file not found", source=str(path))
    data, _ = read_toml(path)
    return _identity(ConfigTable.root(data, source=str(path)).table_at("station", required=False))


def _identity(table: ConfigTable) -> StationIdentity:
    humidity = table.number("humidity_pct", None) if "humidity_pct" in table else None
    if humidity is not None and not 0 <= humidity <= 100:
        raise table.error("humidity_pct", f"is a relative humidity in % (0..100), got {humidity}")
    identity = StationIdentity(
        station_id=table.string("id", "") or None,
        store=table.string("store", "") or None,
        reference=table.boolean("reference", False),
        laboratory=table.string("laboratory", "") or None,
        laboratory_address=table.string("laboratory_address", "") or None,
        customer=table.string("customer", "") or None,
        authorised_by=table.string("authorised_by", "") or None,
        temperature_c=table.number("temperature_c", None) if "temperature_c" in table else None,
        humidity_pct=humidity,
        conditions=table.string("conditions", "") or None,
    )
    table.done()
    return identity


def load_station(path: str | Path) -> Station:
    """Read a station file.

    Raises
    ------
    ProfileError
        Naming the file, the table and the key: missing or unknown, wrong type, out of range.
    """
    path = Path(path)
    if not path.is_file():
        raise ProfileError("station file not found", source=str(path))
    data, _ = read_toml(path)
    return station_from_mapping(data, source=str(path), base_dir=path.parent)


def station_from_mapping(data: Mapping[str, Any], *, source: str, base_dir: Path) -> Station:
    """Build a station from a parsed station file (one of ``[canopen]``, ``[modbus]`` or
    ``[odrive]``)."""
    document = ConfigTable.root(data, source=source)
    if sum(bus in document for bus in ("canopen", "modbus", "odrive")) != 1:
        raise ProfileError("a station has one table [canopen], [modbus] or [odrive]",
                           source=source)
    station: Station
    if "odrive" in document:
        station = read_odrive(document.table_at("odrive"))
    elif "canopen" in document:
        station = _canopen(
            document.table_at("canopen"), document.table_at("scaling", required=False), base_dir
        )
    else:
        station = _modbus(document.table_at("modbus"), base_dir)
    station = replace(station, equipment=read_equipment(document))
    _identity(document.table_at("station", required=False))
    document.done()
    return station


def resolve_fixture(name: str, *, base_dir: Path, source: str) -> Path:
    """A path relative to the station file, else a built-in fixture of that name."""
    candidate = Path(name)
    if not candidate.is_absolute():
        candidate = base_dir / candidate
    if candidate.is_file():
        return candidate
    builtin = builtin_fixture(Path(name).name)
    if builtin.is_file():
        return builtin
    raise ProfileError(
        f"file '{name}' not found (looked in {base_dir} and fixtures/)", source=source
    )


def _canopen(table: ConfigTable, scaling: ConfigTable, base_dir: Path) -> CanOpenStation:
    node_id = table.integer("node_id")
    if not 1 <= node_id <= 127:
        raise table.error("node_id", f"must be 1..127, got {node_id}")
    station = CanOpenStation(
        source=table.source,
        interface=table.string("interface"),
        channel=table.string("channel"),
        bitrate=table.integer("bitrate", 1_000_000),
        node_id=node_id,
        eds_path=resolve_fixture(table.string("eds"), base_dir=base_dir, source=table.source),
        sync_period_s=table.positive("sync_period_s", 0.001),
        sync_pacing=table.choice("sync_pacing", SYNC_PACINGS, "realtime"),
        sync_producer=table.choice("sync_producer", SYNC_PRODUCERS, "host"),
        max_sync_interval_sd_s=table.optional_positive("max_sync_interval_sd_s"),
        max_bus_load=table.positive("max_bus_load", 0.6),
        sdo_timeout_s=table.positive("sdo_timeout_s", 0.5),
        pdo_timeout_s=table.positive("pdo_timeout_s", 0.1),
        heartbeat_period_s=table.positive("heartbeat_period_s", 0.1),
        heartbeat_timeout_s=table.positive("heartbeat_timeout_s", 1.0),
        state_timeout_s=table.positive("state_timeout_s", 1.0),
        acquisition=table.choice("acquisition", ACQUISITIONS, "stream"),
        lost_sample_fraction=table.non_negative("lost_sample_fraction", 0.02),
        torque_sample=table.choice("torque_sample", TORQUE_SAMPLES, "auto"),
        control_period_s=table.optional_positive("control_period_s"),
        rated_torque_nm=scaling.optional_positive("rated_torque_nm"),
        rated_current_a=scaling.optional_positive("rated_current_a"),
        counts_per_rev=scaling.integer("counts_per_rev") if "counts_per_rev" in scaling else None,
        velocity_units_per_rad_s=scaling.optional_positive("velocity_units_per_rad_s"),
        quick_stop_option_code=scaling.integer("quick_stop_option_code", 2),
        quick_stop_decel_rad_s2=scaling.positive("quick_stop_decel_rad_s2", 20.0),
        host_node_id=table.integer("host_node_id", 127),
        host_heartbeat_timeout_s=table.positive("host_heartbeat_timeout_s", 1.0),
        abort_connection_option_code=table.integer("abort_connection_option_code", 3),
        can_options=dict(table.table_at("options", required=False).values),  # python-can's
        gimbal=_gimbal(table, base_dir, largest_address=127),
        object_map=_object_map(table, base_dir),
    )
    table.done()
    scaling.done()
    if station.max_bus_load > 1:
        raise table.error("max_bus_load", "is a fraction (0..1]")
    if station.sync_producer != "host" and station.sync_pacing == "lockstep":
        raise table.error("sync_producer", "a producer other than the host needs sync_pacing "
                                           "'realtime' (in lockstep the host's SYNC is the clock)")
    _check_host_watch(table, station)
    return station


def _object_map(table: ConfigTable, base_dir: Path) -> ObjectMap:
    """The drive model's object map: a file beside the station, or a shipped map's name."""
    name = table.string("object_map", GENERIC_MAP)
    try:
        return load_object_map(name, base_dir=base_dir)
    except ProfileError as exc:
        if exc.source:  # the map file itself is wrong: its own line
            raise
        raise table.error("object_map", exc.message) from None


def _gimbal(table: ConfigTable, base_dir: Path, *, largest_address: int) -> GimbalBus:
    """``axes``, ``hold`` and ``emulated_profiles`` of a bus table; every name they use is
    an axis of ``axes``."""
    gimbal = GimbalBus(
        axes=_axes(table.table_at("axes", required=False), largest_address),
        hold=_hold(table.table_at("hold", required=False)),
        emulated_profiles={
            name: resolve_fixture(path, base_dir=base_dir, source=table.source)
            for name, path in _strings(table.table_at("emulated_profiles", required=False))
        },
    )
    for where, names in (("hold.at_rad", gimbal.hold.at_rad),
                         ("emulated_profiles", gimbal.emulated_profiles)):
        unknown = sorted(set(names) - set(gimbal.axes))
        if unknown:
            raise ProfileError(f"{table.table[:-1]}.{where}] names axis '{unknown[0]}', not one "
                               f"of {table.table[:-1]}.axes] "
                               f"({', '.join(sorted(gimbal.axes)) or 'none'})",
                               source=table.source)
    return gimbal


def _axes(table: ConfigTable, largest: int) -> dict[str, int]:
    """``[BUS.axes]``: axis name = node or unit id, each 1..``largest`` and each once."""
    axes = {name: table.integer(name) for name in table.values}
    for name, address in axes.items():
        if not 1 <= address <= largest:
            raise table.error(name, f"is a bus address, 1..{largest}, got {address}")
    if len(set(axes.values())) != len(axes):
        raise ProfileError(f"{table.table} gives two axes one node: {axes}", source=table.source)
    table.done()
    return axes


def _hold(table: ConfigTable) -> HoldSettings:
    default = HoldSettings()
    hold = HoldSettings(
        speed_rad_s=table.positive("speed_rad_s", default.speed_rad_s),
        accel_rad_s2=table.positive("accel_rad_s2", default.accel_rad_s2),
        window_rad=table.positive("window_rad", default.window_rad),
        settle_s=table.non_negative("settle_s", default.settle_s),
        timeout_s=table.positive("timeout_s", default.timeout_s),
        at_rad=_angles(table.table_at("at_rad", required=False)),
    )
    table.done()
    return hold


def _angles(table: ConfigTable) -> dict[str, float]:
    angles = {name: table.number(name) for name in table.values}
    table.done()
    return angles


def _strings(table: ConfigTable) -> list[tuple[str, str]]:
    pairs = [(name, table.string(name)) for name in table.values]
    table.done()
    return pairs


def _check_host_watch(table: ConfigTable, station: CanOpenStation) -> None:
    """The host's heartbeat and the drive's reaction to its loss must be what CiA 301/402
    can express, and the drive must be allowed to miss a few heartbeats."""
    if station.host_node_id in station.gimbal.axes.values():
        raise table.error("host_node_id", f"is node {station.host_node_id} of [canopen.axes]")
    if not 1 <= station.host_node_id <= 127 or station.host_node_id == station.node_id:
        raise table.error("host_node_id", f"must be 1..127 and not the drive's node_id "
                                          f"{station.node_id}, got {station.host_node_id}")
    if station.abort_connection_option_code not in (1, 2, 3):
        raise table.error("abort_connection_option_code", "must be 1 (fault), 2 (disable "
                          "voltage) or 3 (quick stop): a drive whose host died must stop, got "
                          f"{station.abort_connection_option_code}")
    timeout_ms = station.host_heartbeat_timeout_s * 1e3
    if not 2 * station.heartbeat_period_s < station.host_heartbeat_timeout_s or timeout_ms > 65535:
        raise table.error("host_heartbeat_timeout_s", "must be more than two heartbeat periods "
                          f"({2 * station.heartbeat_period_s:g} s) and at most 65.535 s "
                          f"(0x1016, in ms), got {station.host_heartbeat_timeout_s:g} s")


def _modbus(table: ConfigTable, base_dir: Path) -> ModbusStation:
    transport = table.choice("transport", ("tcp", "rtu"), "tcp")
    serial_port = table.string("serial_port", "")
    if transport == "rtu" and not serial_port:
        raise table.error("serial_port", "transport 'rtu' needs it")
    station = ModbusStation(
        source=table.source,
        transport=transport,
        register_map_path=resolve_fixture(
            table.string("register_map"), base_dir=base_dir, source=table.source
        ),
        host=table.string("host", "127.0.0.1"),
        port=table.integer("port", 502),
        serial_port=serial_port,
        baudrate=table.integer("baudrate", 115200),
        parity=table.choice("parity", ("N", "E", "O"), "N"),
        stopbits=table.integer("stopbits", 1),
        unit_id=table.integer("unit_id", 1),
        timeout_s=table.positive("timeout_s", 0.5),
        max_poll_rate_hz=table.positive("max_poll_rate_hz", 1000.0),
        watchdog_s=table.positive("watchdog_s", 0.5),
        torque_sample=table.choice("torque_sample", TORQUE_SAMPLES, "auto"),
        setpoint_lead_periods=table.integer("setpoint_lead_periods", 3),
        acquisition=table.choice("acquisition", ACQUISITIONS, "stream"),
        gimbal=_gimbal(table, base_dir, largest_address=247),
    )
    table.done()
    if station.setpoint_lead_periods < 1:
        raise table.error("setpoint_lead_periods", "must be 1 or more (sample periods)")
    return station
