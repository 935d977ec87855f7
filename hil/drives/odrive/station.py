"""The ``[odrive]`` table of a station file: how the bench reaches one ODrive axis over CAN.

The cyclic message periods are what the ODrive was configured with (odrivetool:
``axis0.config.can.*_msg_rate_ms``); bring-up measures them and refuses a drive that does
not send what the station declares. ``pacing = "lockstep"`` is for the emulator only (it
advances one feedback period per command message); a real ODrive runs on its own clock
(``"realtime"``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from hil.config import ConfigTable
from hil.drives.equipment import Equipment
from hil.drives.odrive.protocol import FRAME_BITS_8, NODE_ID_MAX

PACINGS = ("realtime", "lockstep")
#: which torque a row carries: Get_Torques' Torque_Estimate (firmware 0.6: K_t·Iq measured),
#: its Torque_Target (the torque the controller commands), or K_t·Iq_measured computed here
TORQUE_SOURCES = ("estimate", "target", "kt_iq")
ODRIVE_CONTROL_PERIOD_S = 1 / 8000  # firmware 0.6's control loop (ODrive Pro, S1, Micro)


@dataclass(frozen=True, slots=True, kw_only=True)
class OdriveStation:
    """One ODrive axis on a CAN bus reached through python-can (``[odrive]``).

    The ``*_period_ms`` keys are the ODrive's cyclic message periods: the heartbeat, and
    the feedback a recording's row is made of (encoder estimates, Iq, torques; all three at
    one period, the row period); ``error_period_ms`` 0 is off. ``torque_constant_nm_a`` is
    the ODrive's ``motor.config.torque_constant``: the current limit sent with Set_Limits is
    the unit's torque limit over it, and ``torque_source = "kt_iq"`` multiplies Iq by it.
    ``control_period_s`` is the ODrive's control-loop period (8 kHz in firmware 0.6), stated
    in each recording. ``heartbeat_timeout_s``: no heartbeat for this long (of the drive's
    clock) is a :class:`~hil.errors.DriveCommunicationError`. ``watchdog_timeout_s``: the
    ODrive's own ``axis.config.watchdog_timeout`` (0: the station says it is off); the host
    then sends its hold command at least every quarter of it while the axis is enabled.
    """

    source: str
    interface: str
    channel: str
    bitrate: int = 1_000_000
    node_id: int = 0
    pacing: str = "realtime"
    heartbeat_period_ms: int = 100
    encoder_period_ms: int = 2
    iq_period_ms: int = 2
    torques_period_ms: int = 2
    error_period_ms: int = 0
    torque_constant_nm_a: float = 0.1
    torque_source: str = "estimate"
    current_limit_a: float | None = None
    control_period_s: float = ODRIVE_CONTROL_PERIOD_S
    heartbeat_timeout_s: float = 0.5
    frame_timeout_s: float = 0.5
    state_timeout_s: float = 3.0
    quick_stop_timeout_s: float = 2.0
    watchdog_timeout_s: float = 0.0
    lost_sample_fraction: float = 0.02
    max_bus_load: float = 0.6
    can_options: Mapping[str, Any] = field(default_factory=dict)
    equipment: Equipment = field(default_factory=Equipment)

    @property
    def feedback_period_s(self) -> float:
        """The row period: one set of feedback messages."""
        return self.encoder_period_ms * 1e-3

    @property
    def bus_load(self) -> float:
        """The fraction of the bus the cyclic messages and one command per row take."""
        per_s = 4 / self.feedback_period_s + 1e3 / self.heartbeat_period_ms
        if self.error_period_ms:
            per_s += 1e3 / self.error_period_ms
        return per_s * FRAME_BITS_8 / self.bitrate

    @property
    def where(self) -> str:
        """``odrive node N on INTERFACE CHANNEL``: for every message."""
        return f"odrive node {self.node_id} on {self.interface} {self.channel}"


def read_odrive(table: ConfigTable) -> OdriveStation:
    """``[odrive]`` of a station file.

    Raises
    ------
    ProfileError
        Naming file, table and key: missing, unknown, wrong type, out of range.
    """
    node_id = table.integer("node_id")
    if not 0 <= node_id <= NODE_ID_MAX:
        raise table.error("node_id", f"must be 0..{NODE_ID_MAX} (six bits), got {node_id}")
    periods = {key: table.integer(key, default) for key, default in (
        ("heartbeat_period_ms", 100), ("encoder_period_ms", 2), ("iq_period_ms", 2),
        ("torques_period_ms", 2), ("error_period_ms", 0))}
    for key, value in periods.items():
        low = 0 if key == "error_period_ms" else 1
        if not low <= value <= 10_000:
            raise table.error(key, f"must be {low}..10000 ms (the ODrive's *_msg_rate_ms), "
                                   f"got {value}")
    for key in ("iq_period_ms", "torques_period_ms"):
        if periods[key] != periods["encoder_period_ms"]:
            raise table.error(key, f"must equal encoder_period_ms ({periods['encoder_period_ms']}"
                                   f" ms): a row is one encoder, Iq and torques message each, "
                                   f"got {periods[key]}")
    station = OdriveStation(
        source=table.source,
        interface=table.string("interface"),
        channel=table.string("channel"),
        bitrate=table.integer("bitrate", 1_000_000),
        node_id=node_id,
        pacing=table.choice("pacing", PACINGS, "realtime"),
        heartbeat_period_ms=periods["heartbeat_period_ms"],
        encoder_period_ms=periods["encoder_period_ms"],
        iq_period_ms=periods["iq_period_ms"],
        torques_period_ms=periods["torques_period_ms"],
        error_period_ms=periods["error_period_ms"],
        torque_constant_nm_a=table.positive("torque_constant_nm_a"),
        torque_source=table.choice("torque_source", TORQUE_SOURCES, "estimate"),
        current_limit_a=table.optional_positive("current_limit_a"),
        control_period_s=table.positive("control_period_s", ODRIVE_CONTROL_PERIOD_S),
        heartbeat_timeout_s=table.positive("heartbeat_timeout_s", 0.5),
        frame_timeout_s=table.positive("frame_timeout_s", 0.5),
        state_timeout_s=table.positive("state_timeout_s", 3.0),
        quick_stop_timeout_s=table.positive("quick_stop_timeout_s", 2.0),
        watchdog_timeout_s=table.non_negative("watchdog_timeout_s", 0.0),
        lost_sample_fraction=table.non_negative("lost_sample_fraction", 0.02),
        max_bus_load=table.positive("max_bus_load", 0.6),
        can_options=dict(table.table_at("options", required=False).values),  # python-can's
    )
    table.done()
    _check(table, station)
    return station


def _check(table: ConfigTable, station: OdriveStation) -> None:
    if station.bitrate <= 0:
        raise table.error("bitrate", f"must be above zero, got {station.bitrate}")
    if not 2 * station.heartbeat_period_ms * 1e-3 < station.heartbeat_timeout_s:
        raise table.error("heartbeat_timeout_s", "must be more than two heartbeat periods "
                          f"({2 * station.heartbeat_period_ms:g} ms), got "
                          f"{station.heartbeat_timeout_s:g} s")
    steps = station.feedback_period_s / station.control_period_s
    if abs(steps - round(steps)) > 1e-6 or round(steps) < 1:
        raise table.error("control_period_s", f"the row period {station.encoder_period_ms} ms "
                          "must be a whole number of control periods, got "
                          f"{station.control_period_s:g} s")
    if station.max_bus_load > 1:
        raise table.error("max_bus_load", "is a fraction (0..1]")
    if station.bus_load > station.max_bus_load:
        raise table.error("encoder_period_ms", f"the cyclic messages and commands take "
                          f"{station.bus_load:.0%} of a {station.bitrate / 1e3:g} kbit/s bus, "
                          f"more than max_bus_load {station.max_bus_load:.0%}")
    if station.watchdog_timeout_s and station.watchdog_timeout_s < 4 * station.feedback_period_s:
        raise table.error("watchdog_timeout_s", "must be 0 (off) or at least four row periods "
                          f"({4 * station.feedback_period_s:g} s), got "
                          f"{station.watchdog_timeout_s:g} s")
