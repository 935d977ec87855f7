"""ODrive's CANSimple protocol, firmware 0.6.x: arbitration ids, message layouts, enums.

Implemented from ODrive's public documentation of the CAN protocol for firmware 0.6
("CAN Protocol", docs.odriverobotics.com/v/latest/manual/can-protocol.html, and the
0.6.x DBC file ``odrive-cansimple-0.6.x.dbc`` it publishes): an 11-bit arbitration id
``node_id << 5 | cmd_id``, little-endian payloads, floats as IEEE-754 float32. Requests
(``Get_*``) are remote frames with the command's id; the cyclic messages are sent by the
ODrive at the rates set in ``axis.config.can.*_msg_rate_ms`` (0 = off).

Units are ODrive's: turns, turns/s, N·m, A. Conversion to rad lives in the backend.
Pure functions, no I/O.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntEnum, IntFlag

from hil.errors import DriveCommunicationError

FIRMWARE = "0.6"  # the protocol version implemented here
NODE_ID_MAX = 0x3F  # six bits of node id
CMD_MASK = 0x1F


class Cmd(IntEnum):
    """CANSimple command ids (firmware 0.6)."""

    GET_VERSION = 0x00
    HEARTBEAT = 0x01
    ESTOP = 0x02
    GET_ERROR = 0x03
    RX_SDO = 0x04
    TX_SDO = 0x05
    ADDRESS = 0x06
    SET_AXIS_STATE = 0x07
    GET_ENCODER_ESTIMATES = 0x09
    SET_CONTROLLER_MODE = 0x0B
    SET_INPUT_POS = 0x0C
    SET_INPUT_VEL = 0x0D
    SET_INPUT_TORQUE = 0x0E
    SET_LIMITS = 0x0F
    GET_IQ = 0x14
    GET_TEMPERATURE = 0x15
    REBOOT = 0x16
    GET_BUS_VOLTAGE_CURRENT = 0x17
    CLEAR_ERRORS = 0x18
    GET_TORQUES = 0x1C


class AxisState(IntEnum):
    """``axis.current_state`` / ``Set_Axis_State`` (the states the harness uses and sees)."""

    UNDEFINED = 0
    IDLE = 1
    STARTUP_SEQUENCE = 2
    FULL_CALIBRATION_SEQUENCE = 3
    MOTOR_CALIBRATION = 4
    ENCODER_INDEX_SEARCH = 6
    ENCODER_OFFSET_CALIBRATION = 7
    CLOSED_LOOP_CONTROL = 8


class ControlMode(IntEnum):
    """``controller.config.control_mode``."""

    VOLTAGE_CONTROL = 0
    TORQUE_CONTROL = 1
    VELOCITY_CONTROL = 2
    POSITION_CONTROL = 3


class InputMode(IntEnum):
    """``controller.config.input_mode`` (the harness uses passthrough only)."""

    INACTIVE = 0
    PASSTHROUGH = 1
    VEL_RAMP = 2
    POS_FILTER = 3


class ProcedureResult(IntEnum):
    """The heartbeat's procedure result (the values the harness names)."""

    SUCCESS = 0
    BUSY = 1
    CANCELLED = 2
    DISARMED = 3


class OdriveError(IntFlag):
    """``ODriveError`` of firmware 0.6: the heartbeat's ``Axis_Error`` and ``Get_Error``'s
    ``Active_Errors`` / ``Disarm_Reason``."""

    INITIALIZING = 0x1
    SYSTEM_LEVEL = 0x2
    TIMING_ERROR = 0x4
    MISSING_ESTIMATE = 0x8
    BAD_CONFIG = 0x10
    DRV_FAULT = 0x20
    MISSING_INPUT = 0x40
    DC_BUS_OVER_VOLTAGE = 0x100
    DC_BUS_UNDER_VOLTAGE = 0x200
    DC_BUS_OVER_CURRENT = 0x400
    DC_BUS_OVER_REGEN_CURRENT = 0x800
    CURRENT_LIMIT_VIOLATION = 0x1000
    MOTOR_OVER_TEMP = 0x2000
    INVERTER_OVER_TEMP = 0x4000
    VELOCITY_LIMIT_VIOLATION = 0x8000
    POSITION_LIMIT_VIOLATION = 0x10000
    WATCHDOG_TIMER_EXPIRED = 0x1000000
    ESTOP_REQUESTED = 0x2000000
    SPINOUT_DETECTED = 0x4000000
    BRAKE_RESISTOR_DISARMED = 0x8000000
    THERMISTOR_DISCONNECTED = 0x10000000
    CALIBRATION_ERROR = 0x40000000


def error_names(code: int) -> str:
    """The names of the flags set in ``code`` (``"NONE"`` for 0; unknown bits in hex)."""
    if code == 0:
        return "NONE"
    names = [flag.name for flag in OdriveError if code & flag and flag.name]
    unknown = code & ~sum(OdriveError)
    if unknown:
        names.append(f"0x{unknown:X}")
    return " | ".join(names)


def arbitration_id(node_id: int, cmd: int) -> int:
    """``node_id << 5 | cmd``."""
    if not 0 <= node_id <= NODE_ID_MAX:
        raise ValueError(f"node id must be 0..{NODE_ID_MAX}, got {node_id}")
    return node_id << 5 | (cmd & CMD_MASK)


def split_id(arbitration: int) -> tuple[int, int]:
    """``(node_id, cmd)`` of an 11-bit arbitration id."""
    return arbitration >> 5 & NODE_ID_MAX, arbitration & CMD_MASK


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """Heartbeat (0x01): axis error flags, state, procedure result, trajectory done."""

    axis_error: int
    axis_state: int
    procedure_result: int = 0
    trajectory_done: bool = False


@dataclass(frozen=True, slots=True)
class Version:
    """Get_Version (0x00)."""

    protocol: int
    hw_major: int
    hw_minor: int
    hw_variant: int
    fw_major: int
    fw_minor: int
    fw_revision: int
    fw_unreleased: int

    @property
    def firmware(self) -> str:
        tail = "-dev" if self.fw_unreleased else ""
        return f"{self.fw_major}.{self.fw_minor}.{self.fw_revision}{tail}"

    @property
    def hardware(self) -> str:
        return f"{self.hw_major}.{self.hw_minor}-{self.hw_variant}"


def _need(data: bytes, size: int, what: str) -> None:
    if len(data) < size:
        raise DriveCommunicationError(f"CANSimple {what}: {len(data)} bytes, expected {size}")


def encode_heartbeat(beat: Heartbeat) -> bytes:
    return struct.pack("<IBBBB", beat.axis_error & 0xFFFFFFFF, beat.axis_state,
                       beat.procedure_result, int(beat.trajectory_done), 0)


def decode_heartbeat(data: bytes) -> Heartbeat:
    _need(data, 7, "Heartbeat")
    error, state, result, flags = struct.unpack_from("<IBBB", data)
    return Heartbeat(error, state, result, bool(flags & 1))


def encode_version(version: Version) -> bytes:
    return bytes((version.protocol, version.hw_major, version.hw_minor, version.hw_variant,
                  version.fw_major, version.fw_minor, version.fw_revision,
                  version.fw_unreleased))


def decode_version(data: bytes) -> Version:
    _need(data, 8, "Get_Version")
    return Version(*data[:8])


def encode_address(node_id: int, serial: int) -> bytes:
    """Address (0x06): node id, then the 48-bit serial number."""
    return bytes((node_id,)) + (serial & 0xFFFF_FFFF_FFFF).to_bytes(6, "little") + b"\0"


def decode_address(data: bytes) -> tuple[int, int]:
    _need(data, 7, "Address")
    return data[0], int.from_bytes(data[1:7], "little")


def encode_u32(value: int) -> bytes:
    """Set_Axis_State's payload (and any other single UINT32)."""
    return struct.pack("<I", value & 0xFFFFFFFF)


def decode_u32(data: bytes) -> int:
    _need(data, 4, "UINT32")
    return int(struct.unpack_from("<I", data)[0])


def encode_u32_pair(first: int, second: int) -> bytes:
    """Set_Controller_Mode (control mode, input mode), Get_Error (active, disarm reason)."""
    return struct.pack("<II", first & 0xFFFFFFFF, second & 0xFFFFFFFF)


def decode_u32_pair(data: bytes) -> tuple[int, int]:
    _need(data, 8, "two UINT32")
    first, second = struct.unpack_from("<II", data)
    return int(first), int(second)


def encode_float_pair(first: float, second: float) -> bytes:
    """Set_Input_Vel (vel, torque ff), Set_Limits (vel limit, current limit), and the
    feedback pairs: Get_Encoder_Estimates (pos, vel), Get_Iq (setpoint, measured),
    Get_Torques (target, estimate)."""
    return struct.pack("<ff", first, second)


def decode_float_pair(data: bytes) -> tuple[float, float]:
    _need(data, 8, "two float32")
    first, second = struct.unpack_from("<ff", data)
    return float(first), float(second)


def encode_float(value: float) -> bytes:
    """Set_Input_Torque."""
    return struct.pack("<f", value)


def decode_float(data: bytes) -> float:
    _need(data, 4, "float32")
    return float(struct.unpack_from("<f", data)[0])


FF_SCALE = 0.001  # Set_Input_Pos's Vel_FF and Torque_FF: INT16 in 0.001 units
FF_MAX = 32767 * FF_SCALE


def encode_input_pos(pos_turns: float, vel_ff_turns_s: float = 0.0,
                     torque_ff_nm: float = 0.0) -> bytes:
    """Set_Input_Pos: float32 position, INT16 velocity and torque feed-forwards (×0.001).

    Raises
    ------
    ValueError
        A feed-forward outside the INT16 range (±32.767).
    """
    for name, value in (("velocity", vel_ff_turns_s), ("torque", torque_ff_nm)):
        if not abs(value) <= FF_MAX:
            raise ValueError(f"Set_Input_Pos {name} feed-forward {value:g} outside ±{FF_MAX:g}")
    return struct.pack("<fhh", pos_turns, round(vel_ff_turns_s / FF_SCALE),
                       round(torque_ff_nm / FF_SCALE))


def decode_input_pos(data: bytes) -> tuple[float, float, float]:
    _need(data, 8, "Set_Input_Pos")
    pos, vel, torque = struct.unpack_from("<fhh", data)
    return float(pos), vel * FF_SCALE, torque * FF_SCALE


def float32(value: float) -> float:
    """``value`` as a float32 frame carries it."""
    return float(struct.unpack("<f", struct.pack("<f", value))[0])


TURN_RAD = 2 * math.pi


def rad(turns: float) -> float:
    return turns * TURN_RAD


def turns(rad_value: float) -> float:
    return rad_value / TURN_RAD


# bits of a classic 8-byte data frame with an 11-bit id, worst-case stuffing (for bus load)
FRAME_BITS_8 = 135
