"""Station files (TOML): how this test station reaches its drive.

A *unit profile* describes the unit under test; a *station* describes the bench: which
CAN interface or Modbus link, which node, which object dictionary or register map, and the
scaling between drive units and SI. ``--drive canopen --station FILE`` and
``--drive modbus --station FILE`` read one; the emulator kinds build one in memory.

Paths inside a station file (``eds``, ``register_map``) are relative to the file; a bare
file name that does not exist there is looked up in the built-in ``fixtures/``.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from hil.errors import ProfileError

SYNC_PACINGS = ("realtime", "lockstep")
ACQUISITIONS = ("stream", "recorder", "auto")
TORQUE_SAMPLES = ("auto", "mean", "instantaneous")


@dataclass(frozen=True, slots=True, kw_only=True)
class CanOpenStation:
    """A CiA 402 drive on a CAN bus reached through python-can.

    ``sync_pacing`` is ``"realtime"`` for a real bus (SYNC every ``sync_period_s`` of
    wall-clock time) or ``"lockstep"`` for a drive whose clock *is* the SYNC (an emulator
    or a drive in a SYNC-stepped simulation mode): the next SYNC goes out as soon as the
    previous one was answered. Never use lockstep on a real axis.

    ``torque_sample``: which torque a streamed row carries. ``"auto"`` (default): the torque
    averaged over the SYNC period (0x2077, "Torque actual value averaged" in the EDS) when
    the drive offers it, else 0x6077; ``"mean"`` requires 0x2077; ``"instantaneous"`` always
    0x6077. ``control_period_s``: the drive's control-loop period, for a drive that does not
    report it (the emulator's 0x2200:6); it goes into each recording's metadata.
    """

    source: str
    interface: str
    channel: str
    bitrate: int
    node_id: int
    eds_path: Path
    sync_period_s: float = 0.001
    sync_pacing: str = "realtime"
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
    can_options: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True, kw_only=True)
class ModbusStation:
    """A drive reached over Modbus TCP, or Modbus RTU on a serial port or pyserial URL.

    ``torque_sample``: which torque a row carries. ``"auto"`` (default): the register map's
    ``torque_mean`` (the mean since the previous read, i.e. over the row's own period) when
    the map declares it, else the instantaneous ``torque``; ``"mean"`` requires it;
    ``"instantaneous"`` always ``torque``.
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


Station = CanOpenStation | ModbusStation


def load_station(path: str | Path) -> Station:
    """Read a station file. Raises :class:`ProfileError` naming the file and key."""
    path = Path(path)
    source = str(path)
    if not path.is_file():
        raise ProfileError("station file not found", source=source)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ProfileError(f"not valid TOML: {exc}", source=source) from exc
    return station_from_mapping(data, source=source, base_dir=path.parent)


def station_from_mapping(data: Mapping[str, Any], *, source: str, base_dir: Path) -> Station:
    if "canopen" in data and "modbus" in data:
        raise ProfileError("a station has either [canopen] or [modbus], not both", source=source)
    try:
        if "canopen" in data:
            return _canopen(data["canopen"], data.get("scaling", {}), source, base_dir)
        if "modbus" in data:
            return _modbus(data["modbus"], source, base_dir)
    except (TypeError, ValueError) as exc:
        raise ProfileError(f"bad value: {exc}", source=source) from exc
    raise ProfileError("missing table [canopen] or [modbus]", source=source)


def resolve_fixture(name: str, *, base_dir: Path, source: str) -> Path:
    """A path relative to the station file, else a built-in fixture of that name."""
    candidate = Path(name)
    if not candidate.is_absolute():
        candidate = base_dir / candidate
    if candidate.is_file():
        return candidate
    builtin = Path(str(resources.files("gimbal_hil_fixtures").joinpath(Path(name).name)))
    if builtin.is_file():
        return builtin
    raise ProfileError(
        f"file '{name}' not found (looked in {base_dir} and fixtures/)", source=source
    )


_CANOPEN_KEYS = {
    "interface",
    "channel",
    "bitrate",
    "node_id",
    "eds",
    "sync_period_s",
    "sync_pacing",
    "max_bus_load",
    "sdo_timeout_s",
    "pdo_timeout_s",
    "heartbeat_period_s",
    "heartbeat_timeout_s",
    "state_timeout_s",
    "acquisition",
    "lost_sample_fraction",
    "options",
    "torque_sample",
    "control_period_s",
}
_SCALING_KEYS = {
    "rated_torque_nm",
    "rated_current_a",
    "counts_per_rev",
    "velocity_units_per_rad_s",
    "quick_stop_option_code",
    "quick_stop_decel_rad_s2",
}


def _canopen(
    table: Mapping[str, Any], scaling: Mapping[str, Any], source: str, base_dir: Path
) -> CanOpenStation:
    _no_unknown(table, _CANOPEN_KEYS, f"{source} [canopen]")
    _no_unknown(scaling, _SCALING_KEYS, f"{source} [scaling]")
    for key in ("interface", "channel", "node_id", "eds"):
        if key not in table:
            raise ProfileError(f"[canopen] lacks '{key}'", source=source)
    node_id = int(table["node_id"])
    if not 1 <= node_id <= 127:
        raise ProfileError(f"[canopen] node_id must be 1..127, got {node_id}", source=source)
    pacing = str(table.get("sync_pacing", "realtime"))
    if pacing not in SYNC_PACINGS:
        raise ProfileError(f"[canopen] sync_pacing must be one of {SYNC_PACINGS}", source=source)
    acquisition = str(table.get("acquisition", "stream"))
    if acquisition not in ACQUISITIONS:
        raise ProfileError(f"[canopen] acquisition must be one of {ACQUISITIONS}", source=source)
    torque_sample = str(table.get("torque_sample", "auto"))
    if torque_sample not in TORQUE_SAMPLES:
        raise ProfileError(
            f"[canopen] torque_sample must be one of {TORQUE_SAMPLES}", source=source
        )
    where = f"{source} [canopen]"
    station = CanOpenStation(
        source=source,
        interface=str(table["interface"]),
        channel=str(table["channel"]),
        bitrate=int(table.get("bitrate", 1_000_000)),
        node_id=node_id,
        eds_path=resolve_fixture(str(table["eds"]), base_dir=base_dir, source=source),
        sync_period_s=_pos(table, "sync_period_s", 0.001, where),
        sync_pacing=pacing,
        max_bus_load=_pos(table, "max_bus_load", 0.6, where),
        sdo_timeout_s=_pos(table, "sdo_timeout_s", 0.5, where),
        pdo_timeout_s=_pos(table, "pdo_timeout_s", 0.1, where),
        heartbeat_period_s=_pos(table, "heartbeat_period_s", 0.1, where),
        heartbeat_timeout_s=_pos(table, "heartbeat_timeout_s", 1.0, where),
        state_timeout_s=_pos(table, "state_timeout_s", 1.0, where),
        acquisition=acquisition,
        lost_sample_fraction=float(table.get("lost_sample_fraction", 0.02)),
        torque_sample=torque_sample,
        control_period_s=_opt(table, "control_period_s", where),
        rated_torque_nm=_opt(scaling, "rated_torque_nm", f"{source} [scaling]"),
        rated_current_a=_opt(scaling, "rated_current_a", f"{source} [scaling]"),
        counts_per_rev=None if "counts_per_rev" not in scaling else int(scaling["counts_per_rev"]),
        velocity_units_per_rad_s=_opt(scaling, "velocity_units_per_rad_s", f"{source} [scaling]"),
        quick_stop_option_code=int(scaling.get("quick_stop_option_code", 2)),
        quick_stop_decel_rad_s2=_pos(scaling, "quick_stop_decel_rad_s2", 20.0, source),
        can_options=dict(table.get("options", {})),
    )
    if station.max_bus_load > 1:
        raise ProfileError("[canopen] max_bus_load is a fraction (0..1]", source=source)
    return station


_MODBUS_KEYS = {
    "transport",
    "register_map",
    "host",
    "port",
    "serial_port",
    "baudrate",
    "parity",
    "stopbits",
    "unit_id",
    "timeout_s",
    "max_poll_rate_hz",
    "watchdog_s",
    "torque_sample",
}


def _modbus(table: Mapping[str, Any], source: str, base_dir: Path) -> ModbusStation:
    _no_unknown(table, _MODBUS_KEYS, f"{source} [modbus]")
    transport = str(table.get("transport", "tcp"))
    if transport not in ("tcp", "rtu"):
        raise ProfileError("[modbus] transport must be 'tcp' or 'rtu'", source=source)
    if "register_map" not in table:
        raise ProfileError("[modbus] lacks 'register_map'", source=source)
    if transport == "rtu" and not table.get("serial_port"):
        raise ProfileError("[modbus] transport 'rtu' needs 'serial_port'", source=source)
    torque_sample = str(table.get("torque_sample", "auto"))
    if torque_sample not in TORQUE_SAMPLES:
        raise ProfileError(f"[modbus] torque_sample must be one of {TORQUE_SAMPLES}", source=source)
    where = f"{source} [modbus]"
    return ModbusStation(
        source=source,
        transport=transport,
        register_map_path=resolve_fixture(
            str(table["register_map"]), base_dir=base_dir, source=source
        ),
        host=str(table.get("host", "127.0.0.1")),
        port=int(table.get("port", 502)),
        serial_port=str(table.get("serial_port", "")),
        baudrate=int(table.get("baudrate", 115200)),
        parity=str(table.get("parity", "N")),
        stopbits=int(table.get("stopbits", 1)),
        unit_id=int(table.get("unit_id", 1)),
        timeout_s=_pos(table, "timeout_s", 0.5, where),
        max_poll_rate_hz=_pos(table, "max_poll_rate_hz", 1000.0, where),
        watchdog_s=_pos(table, "watchdog_s", 0.5, where),
        torque_sample=torque_sample,
    )


def _no_unknown(table: Mapping[str, Any], known: set[str], source: str) -> None:
    if not isinstance(table, Mapping):
        raise ProfileError("must be a table", source=source)
    unknown = sorted(set(table) - known)
    if unknown:
        raise ProfileError(f"unknown key(s) {', '.join(unknown)}", source=source)


def _pos(table: Mapping[str, Any], key: str, default: float, source: str) -> float:
    value = float(table.get(key, default))
    if not (math.isfinite(value) and value > 0):
        raise ProfileError(f"'{key}' must be a positive number, got {value!r}", source=source)
    return value


def _opt(table: Mapping[str, Any], key: str, source: str) -> float | None:
    return None if key not in table else _pos(table, key, 1.0, source)
