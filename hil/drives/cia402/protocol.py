"""CiA 402 vocabulary: states, controlwords, modes, the PDO layout we configure, bus load."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from hil.motion import Mode, PositionHarmonic

# statusword masks (CiA 402 table 30) -> state name
_STATES = (
    (0x4F, 0x00, "NOT READY TO SWITCH ON"),
    (0x4F, 0x40, "SWITCH ON DISABLED"),
    (0x6F, 0x21, "READY TO SWITCH ON"),
    (0x6F, 0x23, "SWITCHED ON"),
    (0x6F, 0x27, "OPERATION ENABLED"),
    (0x6F, 0x07, "QUICK STOP ACTIVE"),
    (0x4F, 0x0F, "FAULT REACTION ACTIVE"),
    (0x4F, 0x08, "FAULT"),
)
SW_FAULT = 0x0008

CW_DISABLE_VOLTAGE = 0x0000
CW_QUICK_STOP = 0x0002
CW_SHUTDOWN = 0x0006
CW_SWITCH_ON = 0x0007
CW_ENABLE_OPERATION = 0x000F
CW_FAULT_RESET = 0x0080

# 0x60C0 interpolation sub mode select: 0 is CiA 402 linear interpolation; negative codes are
# manufacturer-specific (the object map's interpolation_codes)
INTERPOLATION_UNKNOWN = "unknown"

# (mode code, name) in order of preference for each excitation mode
MODE_CANDIDATES: dict[Mode, tuple[tuple[int, str], ...]] = {
    Mode.VELOCITY: ((9, "cyclic synchronous velocity"), (3, "profile velocity")),
    Mode.TORQUE: ((10, "cyclic synchronous torque"), (4, "profile torque")),
    Mode.POSITION: ((8, "cyclic synchronous position"),),
}
MODE_SUPPORT_BIT = {1: 0x01, 3: 0x04, 4: 0x08, 6: 0x20, 7: 0x40, 8: 0x80, 9: 0x100, 10: 0x200}
TARGET_OBJECT = {
    Mode.VELOCITY: (0x60FF, "i"),
    Mode.TORQUE: (0x6071, "h"),
    Mode.POSITION: (0x607A, "i"),
}

# The PDO layout the backend writes into the drive (all synchronous, type 1):
# RPDO n+1 = controlword + the target of one mode (velocity: + the torque offset 0x60B2, the
# feedforward a drive adds when its firmware has it); TPDO1/TPDO2 = the feedback.
TORQUE_OFFSET = 0x60B2  # INTEGER16, per-mille of 0x6076 like the target torque
RPDO_LAYOUT: dict[Mode, tuple[int, tuple[tuple[int, int, int], ...]]] = {
    Mode.VELOCITY: (1, ((0x6040, 0, 16), (0x60FF, 0, 32), (TORQUE_OFFSET, 0, 16))),
    Mode.TORQUE: (2, ((0x6040, 0, 16), (0x6071, 0, 16))),
    Mode.POSITION: (3, ((0x6040, 0, 16), (0x607A, 0, 32))),
}
_HARMONIC = struct.Struct("<Hff")


def pack_harmonics(harmonics: tuple[PositionHarmonic, ...]) -> bytes:
    """A compensation table's DOMAIN (the object map's ``compensation_table``, subs 1, 2):
    UNSIGNED16 count, then per harmonic UNSIGNED16 order, REAL32 amplitude (N·m, or
    relative for K_t ripple), REAL32 phase (rad)."""
    return struct.pack("<H", len(harmonics)) + b"".join(
        _HARMONIC.pack(h.order, h.amplitude, h.phase_rad) for h in harmonics)


def unpack_harmonics(data: bytes) -> tuple[PositionHarmonic, ...]:
    """Inverse of :func:`pack_harmonics`.

    Raises
    ------
    ValueError
        The length does not match the count.
    """
    (count,) = struct.unpack_from("<H", data)
    if len(data) != 2 + count * _HARMONIC.size:
        raise ValueError(f"compensation table data of {len(data)} bytes for {count} harmonics")
    return tuple(PositionHarmonic(order=o, amplitude=a, phase_rad=p)
                 for o, a, p in _HARMONIC.iter_unpack(data[2:]))


RPDO_FORMAT: dict[Mode, str] = {Mode.VELOCITY: "<Hih", Mode.TORQUE: "<Hh", Mode.POSITION: "<Hi"}
"""struct format of each mode's RPDO (controlword, target[, torque offset])."""
TpdoLayout = tuple[tuple[int, tuple[tuple[int, int, int], ...]], ...]
TPDO_LAYOUT: TpdoLayout = (
    (1, ((0x6041, 0, 16), (0x6064, 0, 32), (0x6061, 0, 8))),  # "<HIb": statusword, position, mode
    (2, ((0x606C, 0, 32), (0x6077, 0, 16), (0x6078, 0, 16))),  # "<ihh": velocity, torque, current
)


def tpdo_layout_mean(index: int, subindex: int) -> TpdoLayout:
    """:data:`TPDO_LAYOUT` with the SYNC-period torque average (the object map's 16-bit
    ``torque_mean``) in 0x6077's place: the frames and the bus load stay the same."""
    return (TPDO_LAYOUT[0], (2, ((0x606C, 0, 32), (index, subindex, 16), (0x6078, 0, 16))))


TPDO1_FORMAT = "<Hib"
TPDO2_FORMAT = "<ihh"


def state_of(statusword: int) -> str:
    """The CiA 402 state name of ``statusword`` (``"UNKNOWN"`` if no mask matches)."""
    for mask, value, name in _STATES:
        if statusword & mask == value:
            return name
    return "UNKNOWN"


def frame_bits(data_bytes: int) -> int:
    """Worst-case bits on the wire of one standard-ID CAN 2.0A data frame with stuffing
    (44 + 8n bits of frame, stuff bits over the 34 + 8n stuffable ones, 3 of intermission)."""
    stuffable = 34 + 8 * data_bytes
    return 44 + 8 * data_bytes + (stuffable - 1) // 4 + 3


def cycle_bits(rpdo_bytes: int, tpdo_bytes: tuple[int, ...]) -> int:
    """Bits of one SYNC cycle: SYNC, one RPDO, the TPDOs."""
    return frame_bits(0) + frame_bits(rpdo_bytes) + sum(frame_bits(n) for n in tpdo_bytes)


def stream_frame_bytes() -> tuple[int, tuple[int, ...]]:
    """Data bytes of our largest RPDO and of each TPDO."""
    rpdo = max(sum(bits for *_, bits in entries) for _, entries in RPDO_LAYOUT.values()) // 8
    return rpdo, tuple(sum(bits for *_, bits in entries) // 8 for _, entries in TPDO_LAYOUT)


def max_stream_rate_hz(bitrate: int, max_bus_load: float) -> float:
    """Highest SYNC rate at which our PDO layout keeps the bus below ``max_bus_load``."""
    return bitrate * max_bus_load / cycle_bits(*stream_frame_bytes())


@dataclass(frozen=True, slots=True, kw_only=True)
class Scaling:
    """Drive units <-> SI; lives only inside the backend."""

    counts_per_rev: int
    velocity_units_per_rad_s: float
    rated_torque_nm: float
    rated_current_a: float

    @property
    def counts_per_rad(self) -> float:
        """Position increments per radian."""
        return self.counts_per_rev / (2 * math.pi)

    def to_drive(self, mode: Mode, value_si: float) -> int:
        """A target of ``mode`` in drive units (increments, velocity units, ‰ rated)."""
        if mode is Mode.VELOCITY:
            return round(value_si * self.velocity_units_per_rad_s)
        if mode is Mode.TORQUE:
            return round(value_si / self.rated_torque_nm * 1e3)
        return round(value_si * self.counts_per_rad)

    def to_si(self, mode: Mode, value_drive: float) -> float:
        """A value of ``mode`` in drive units, in SI (rad, rad/s, N·m)."""
        if mode is Mode.VELOCITY:
            return value_drive / self.velocity_units_per_rad_s
        if mode is Mode.TORQUE:
            return value_drive * self.rated_torque_nm / 1e3
        return value_drive / self.counts_per_rad
