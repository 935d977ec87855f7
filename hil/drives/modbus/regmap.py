"""Register maps (TOML, one per drive model): where each value lives and how it is coded."""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass, replace
from itertools import pairwise
from pathlib import Path
from typing import Literal

import numpy as np

from hil.config import ConfigTable, read_toml
from hil.errors import ProfileError

TYPES = {
    "int16": ("h", 1),
    "uint16": ("H", 1),
    "int32": ("i", 2),
    "uint32": ("I", 2),
    "float32": ("f", 2),
}
ORDERS = ("big", "little")
CONTROL_BITS = {"enable": 0, "quick_stop": 1, "fault_reset": 2}
STATUS_BITS = {"enabled": 0, "fault": 1, "quick_stop_active": 2}
MODES = {"torque": 1, "velocity": 2, "position": 3}
REQUIRED = (
    "status_word",
    "fault_code",
    "position",
    "velocity",
    "torque",
    "control_word",
    "mode",
    "velocity_cmd",
    "torque_cmd",
    "position_cmd",
)
FEEDBACK = ("status_word", "fault_code", "position", "velocity", "torque", "current")
# optional: the drive's free-running clock, latched with the feedback (unsigned, read-only,
# scale = seconds per count); the backend then times samples by the drive, not the host
TIMESTAMP = "timestamp"
# optional: the drive ramps linearly from the setpoint in effect to each newly written one
# over this time (writable, scale = seconds per count); the backend sets it to its period
SETPOINT_INTERPOLATION = "setpoint_interpolation_time"
# optional: the mean of the torque commanded per control period over the control periods
# since the previous read of this register, up to the latched sample (signed, N·m); reading
# it restarts the average. With it, optionally, the length of that average (unsigned,
# seconds per count), latched with it.
# optional: the torque offset (feedforward, signed, N·m, writable) a drive whose firmware has
# feedforward adds to its torque command
TORQUE_OFFSET = "torque_offset"
# optional: the drive's digital outputs (unsigned, writable), bit n = output n: a bench's
# locked-rotor clamp is wired to one ([locked_rotor] output_bit)
DIGITAL_OUTPUTS = "digital_outputs"
TORQUE_MEAN = "torque_mean"
TORQUE_MEAN_WINDOW = "torque_mean_window"
# optional, all or none: the drive recorder (a waveform table the drive plays at its control
# rate while it captures position, velocity, torque and current per sample; the host writes
# the table and reads the captures back through windows of ``length`` samples at
# ``recorder_index``). Its rate is 1 / the device's ``control_period_s``.
RECORDER_CONTROL = "recorder_control"  # write 1: play the table (trigger); 2: abort
RECORDER_STATE = "recorder_state"  # 0 idle, 1 busy, 2 done, 3 aborted (fault, stop, disable)
RECORDER_LENGTH = "recorder_length"  # samples of the table to play
RECORDER_DIVIDER = "recorder_divider"  # control periods per sample (table held, capture decimated)
RECORDER_SAMPLES = "recorder_samples"  # samples captured so far
RECORDER_CAPACITY = "recorder_capacity"  # the most samples the table and the buffers hold
RECORDER_INDEX = "recorder_index"  # the first sample of every window
RECORDER_WAVEFORM = "recorder_waveform"  # window of the table (the mode's *_cmd units)
RECORDER_COLUMNS = {  # capture windows, by the feedback register whose values they hold
    "position": "recorder_position",
    "velocity": "recorder_velocity",
    "torque": "recorder_torque",
    "current": "recorder_current",
}
RECORDER = (RECORDER_CONTROL, RECORDER_STATE, RECORDER_LENGTH, RECORDER_DIVIDER,
            RECORDER_SAMPLES, RECORDER_CAPACITY, RECORDER_INDEX, RECORDER_WAVEFORM,
            *RECORDER_COLUMNS.values())
RECORDER_IDLE, RECORDER_BUSY, RECORDER_DONE, RECORDER_ABORTED = 0, 1, 2, 3
RECORDER_START, RECORDER_ABORT, RECORDER_START_WITH_OFFSET = 1, 2, 3
# optional, with the recorder: what its torque capture holds at a divider n > 1 (0: the
# torque commanded over the captured control period; 1: the mean of the torque commanded
# per control period over the sample's n periods up to and including the captured one, the
# torque_mean register's definition), and a window of a torque offset table (the
# torque_offset register's units) the drive adds sample by sample to its torque command
# while it plays the table, when triggered with 3
RECORDER_TORQUE_SAMPLE = "recorder_torque_sample"
RECORDER_TORQUE_MEAN = 1
RECORDER_OFFSET = "recorder_offset"
# optional, all or none: the cogging compensation table (the drive adds Σ cogging to its
# torque command and divides it by 1 + Σ K_t ripple when its firmware has cogging
# compensation), a harmonic per slot: its order (0: the slot is unused), amplitude (N·m, or
# relative for the ripple) and phase (rad); windows of one length, written in one request
COMPENSATION = {
    "cogging": ("compensation_cogging_order", "compensation_cogging_amplitude",
                "compensation_cogging_phase"),
    "kt_ripple": ("compensation_ripple_order", "compensation_ripple_amplitude",
                  "compensation_ripple_phase"),
}
COMPENSATION_REGISTERS = tuple(name for names in COMPENSATION.values() for name in names)


@dataclass(frozen=True, slots=True, kw_only=True)
class Register:
    name: str
    address: int
    type: str
    word_order: str
    byte_order: str
    scale: float
    unit: str
    writable: bool
    length: int = 1  # values in a row from ``address`` (a window of the drive recorder)

    @property
    def count(self) -> int:
        """Registers of one value."""
        return TYPES[self.type][1]

    @property
    def words(self) -> int:
        """Registers of all ``length`` values."""
        return self.count * self.length

    @property
    def modulus(self) -> int:
        """Raw counts after which an unsigned register wraps to 0."""
        return 1 << (16 * self.count)

    def _format(self) -> str:
        return (">" if self.byte_order == "big" else "<") + TYPES[self.type][0]

    def decode(self, words: list[int]) -> float:
        """Registers (16-bit ints as the wire carries them) -> SI value."""
        ordered = list(words) if self.word_order == "big" or self.count == 1 else words[::-1]
        order: Literal["big", "little"] = "big" if self.byte_order == "big" else "little"
        raw = b"".join(w.to_bytes(2, order) for w in ordered)
        return float(struct.unpack(self._format(), raw)[0]) * self.scale

    def encode(self, value_si: float) -> list[int]:
        raw_value: float | int = value_si / self.scale
        if self.type != "float32":
            raw_value = round(raw_value)
        data = struct.pack(self._format(), raw_value)
        order: Literal["big", "little"] = "big" if self.byte_order == "big" else "little"
        words = [int.from_bytes(data[i : i + 2], order) for i in range(0, len(data), 2)]
        return words if self.word_order == "big" or self.count == 1 else words[::-1]

    def decode_raw(self, words: list[int]) -> np.ndarray:
        """The ``length`` raw values (counts, unscaled) of a window's registers."""
        unit = replace(self, scale=1.0)
        return np.asarray([unit.decode(words[i : i + self.count])
                           for i in range(0, len(words), self.count)], dtype=np.float64)

    def encode_raw(self, raw: np.ndarray) -> list[int]:
        """Registers holding the raw values ``raw`` (counts, in this register's type)."""
        unit = replace(self, scale=1.0)
        return [w for value in raw for w in unit.encode(float(value))]

    @property
    def raw_range(self) -> tuple[float, float]:
        """The raw values this register's type holds."""
        bits = 16 * self.count
        if self.type.startswith("uint"):
            return 0.0, float((1 << bits) - 1)
        if self.type == "float32":
            return -3.4e38, 3.4e38
        return float(-(1 << (bits - 1))), float((1 << (bits - 1)) - 1)


@dataclass(frozen=True, slots=True, kw_only=True)
class RegisterMap:
    source: str
    model: str
    registers: Mapping[str, Register]
    max_registers_per_read: int
    frame_gap_s: float
    control_period_s: float | None  # the drive's loop period: the torque register holds one
    control_bits: Mapping[str, int]
    status_bits: Mapping[str, int]
    modes: Mapping[str, int]

    def __getitem__(self, name: str) -> Register:
        return self.registers[name]

    def blocks(self, names: tuple[str, ...]) -> list[tuple[int, int]]:
        """Contiguous (address, count) reads covering ``names``, each within the limit."""
        spans = sorted(
            (self.registers[n].address, self.registers[n].address + self.registers[n].words)
            for n in names
            if n in self.registers
        )
        blocks: list[list[int]] = []
        for start, stop in spans:
            # one read may span unused registers as long as it stays within the limit
            if blocks and stop - blocks[-1][0] <= self.max_registers_per_read:
                blocks[-1][1] = max(blocks[-1][1], stop)
            else:
                blocks.append([start, stop])
        return [(start, stop - start) for start, stop in blocks]

    @property
    def has_recorder(self) -> bool:
        """The map declares the drive recorder (and the control period that is its rate)."""
        return RECORDER_CONTROL in self.registers

    @property
    def recorder_window(self) -> int:
        """Samples per window of the recorder (its waveform's; the capture's may differ)."""
        return self.registers[RECORDER_WAVEFORM].length

    @property
    def capture_window(self) -> int:
        """Samples per capture window (the same for every column)."""
        return self.registers[RECORDER_COLUMNS["position"]].length

    @property
    def has_compensation(self) -> bool:
        """The map declares the cogging compensation table."""
        return COMPENSATION_REGISTERS[0] in self.registers

    def compensation_span(self) -> tuple[int, int]:
        """(address, count) of the compensation table's registers, one write."""
        start = min(self.registers[n].address for n in COMPENSATION_REGISTERS)
        stop = max(self.registers[n].address + self.registers[n].words
                   for n in COMPENSATION_REGISTERS)
        return start, stop - start

    @property
    def address_end(self) -> int:
        """One past the highest register the map declares."""
        return max(r.address + r.words for r in self.registers.values())


def load_register_map(path: str | Path) -> RegisterMap:
    """Read a register map.

    Raises
    ------
    ProfileError
        Naming the file, the table and the key: missing or unknown, wrong type, out of range,
        or a register that cannot serve its role.
    """
    path = Path(path)
    source = str(path)
    document = ConfigTable.root(read_toml(path)[0], source=source)
    device = document.table_at("device", required=False)
    byte_order = device.choice("byte_order", ORDERS, "big")
    word_order = device.choice("word_order", ORDERS, "big")
    model = device.string("model", path.stem)
    max_registers_per_read = device.integer("max_registers_per_read", 125)
    frame_gap_s = device.non_negative("frame_gap_s", 0.0)
    control_period = device.optional_positive("control_period_s")
    device.done()
    registers = {
        name: _register(name, table, byte_order, word_order)
        for name, table in document.tables("registers").items()
    }
    missing = [name for name in REQUIRED if name not in registers]
    if missing:
        raise ProfileError(f"[registers] lacks {', '.join(missing)}", source=source)
    bits = document.table_at("bits", required=False)
    control_bits = _integers(bits.table_at("control", required=False), CONTROL_BITS)
    status_bits = _integers(bits.table_at("status", required=False), STATUS_BITS)
    bits.done()
    modes = _integers(document.table_at("modes", required=False), MODES)
    document.done()
    for name in ("control_word", "mode", "velocity_cmd", "torque_cmd", "position_cmd"):
        if not registers[name].writable:
            raise ProfileError(
                f"register '{name}' must be writable (access = \"rw\")", source=source
            )
    mean = registers.get(TORQUE_MEAN)
    if mean is not None and mean.type not in ("int16", "int32", "float32"):
        raise ProfileError(
            f"register '{TORQUE_MEAN}' must be int16, int32 or float32, got '{mean.type}'",
            source=f"{source} [registers.{TORQUE_MEAN}]",
        )
    if TORQUE_MEAN_WINDOW in registers and mean is None:
        raise ProfileError(
            f"register '{TORQUE_MEAN_WINDOW}' without '{TORQUE_MEAN}'",
            source=f"{source} [registers.{TORQUE_MEAN_WINDOW}]",
        )
    for name in (TIMESTAMP, SETPOINT_INTERPOLATION, TORQUE_MEAN_WINDOW):
        register = registers.get(name)
        if register is not None and register.type not in ("uint16", "uint32"):
            raise ProfileError(
                f"register '{name}' must be uint16 or uint32, got '{register.type}'",
                source=f"{source} [registers.{name}]",
            )
        if register is not None and register.scale <= 0:
            raise ProfileError(
                f"register '{name}' needs a positive scale (seconds per count)",
                source=f"{source} [registers.{name}]",
            )
    _check_recorder(registers, control_period, max_registers_per_read, source)
    _check_compensation(registers, source)
    if SETPOINT_INTERPOLATION in registers and not registers[SETPOINT_INTERPOLATION].writable:
        raise ProfileError(
            f"register '{SETPOINT_INTERPOLATION}' must be writable (access = \"rw\")",
            source=f"{source} [registers.{SETPOINT_INTERPOLATION}]",
        )
    return RegisterMap(
        source=source,
        model=model,
        registers=registers,
        max_registers_per_read=max_registers_per_read,
        frame_gap_s=frame_gap_s,
        control_period_s=control_period,
        control_bits=control_bits,
        status_bits=status_bits,
        modes=modes,
    )


def _check_recorder(registers: Mapping[str, Register], control_period_s: float | None,
                    max_registers_per_read: int, source: str) -> None:
    """The drive recorder's registers: all or none, the windows' shapes, and reads and
    writes that fit one request (a capture window with its index, the index with the
    waveform window: the host reads and writes them together)."""
    declared = [name for name in RECORDER if name in registers]
    if not declared:
        for name, register in registers.items():
            if register.length != 1 and name not in COMPENSATION_REGISTERS:
                raise ProfileError(f"register '{name}': 'length' is for the recorder's and "
                                   "the compensation table's windows",
                                   source=f"{source} [registers.{name}]")
        return
    missing = [name for name in RECORDER if name not in registers]
    if missing:
        raise ProfileError(f"a drive recorder needs every one of its registers; [registers] "
                           f"lacks {', '.join(missing)}", source=source)
    if control_period_s is None:
        raise ProfileError("a drive recorder needs [device] control_period_s (its rate)",
                           source=source)
    for name in (RECORDER_CONTROL, RECORDER_LENGTH, RECORDER_DIVIDER, RECORDER_INDEX,
                 RECORDER_WAVEFORM):
        if not registers[name].writable:
            raise ProfileError(f"register '{name}' must be writable (access = \"rw\")",
                               source=f"{source} [registers.{name}]")
    for name in (RECORDER_CONTROL, RECORDER_STATE, RECORDER_LENGTH, RECORDER_DIVIDER,
                 RECORDER_SAMPLES, RECORDER_CAPACITY, RECORDER_INDEX):
        if registers[name].type not in ("uint16", "uint32") or registers[name].length != 1:
            raise ProfileError(f"register '{name}' must be one uint16 or uint32",
                               source=f"{source} [registers.{name}]")
    columns = [registers[name] for name in RECORDER_COLUMNS.values()]
    if len({c.length for c in columns}) != 1 or registers[RECORDER_WAVEFORM].type == "float32":
        raise ProfileError("the recorder's capture windows must have one length, and its "
                           "waveform an integer type", source=source)
    index = registers[RECORDER_INDEX]
    capture = sorted((c.address, c.address + c.words) for c in columns)
    waveform = registers[RECORDER_WAVEFORM]
    if (any(a[1] != b[0] for a, b in pairwise(capture))
            or capture[-1][1] != index.address or index.address + index.count != waveform.address
            or index.address + index.count - capture[0][0] > max_registers_per_read
            or index.count + waveform.words > 123):
        raise ProfileError(
            "the recorder's capture windows must be contiguous and end at "
            f"'{RECORDER_INDEX}', which the waveform window follows: one read of at most "
            f"{max_registers_per_read} registers (max_registers_per_read) and one write of at "
            "most 123", source=source)
    sample = registers.get(RECORDER_TORQUE_SAMPLE)
    if sample is not None and (not sample.writable or sample.type not in ("uint16", "uint32")
                               or sample.length != 1):
        raise ProfileError(f"register '{RECORDER_TORQUE_SAMPLE}' must be one writable uint16 "
                           "or uint32", source=f"{source} [registers.{RECORDER_TORQUE_SAMPLE}]")
    offset = registers.get(RECORDER_OFFSET)
    if offset is not None and (not offset.writable or offset.type == "float32"
                               or index.count + offset.words > 123):
        raise ProfileError(f"register '{RECORDER_OFFSET}' must be a writable integer window "
                           f"that one write of at most 123 registers carries",
                           source=f"{source} [registers.{RECORDER_OFFSET}]")


def _check_compensation(registers: Mapping[str, Register], source: str) -> None:
    """The compensation table's registers: all or none, writable, windows of one length
    (orders an integer type), one write of at most 123 registers."""
    declared = [name for name in COMPENSATION_REGISTERS if name in registers]
    if not declared:
        return
    missing = [name for name in COMPENSATION_REGISTERS if name not in registers]
    if missing:
        raise ProfileError(f"a compensation table needs every one of its registers; "
                           f"[registers] lacks {', '.join(missing)}", source=source)
    windows = [registers[name] for name in COMPENSATION_REGISTERS]
    spans = sorted((w.address, w.address + w.words) for w in windows)
    orders = [registers[names[0]] for names in COMPENSATION.values()]
    if (len({w.length for w in windows}) != 1 or not all(w.writable for w in windows)
            or any(o.type == "float32" for o in orders)
            or any(a[1] != b[0] for a, b in pairwise(spans))
            or spans[-1][1] - spans[0][0] > 123):
        raise ProfileError("the compensation table's registers must be writable windows of "
                           "one length (orders an integer type), contiguous: one write of at "
                           "most 123 registers", source=source)


def _integers(table: ConfigTable, defaults: Mapping[str, int]) -> dict[str, int]:
    """A table of named integers (bit numbers, mode values); names other than the defaults'
    are refused."""
    values = {key: table.integer(key, default) for key, default in defaults.items()}
    table.done()
    return values


def _register(name: str, table: ConfigTable, byte_order: str, word_order: str) -> Register:
    scale = table.number("scale", 1.0)
    if scale == 0:
        raise table.error("scale", "must not be 0")
    register = Register(
        name=name,
        address=table.integer("address"),
        type=table.choice("type", tuple(TYPES)),
        word_order=table.choice("word_order", ORDERS, word_order),
        byte_order=byte_order,
        scale=scale,
        unit=table.string("unit", ""),
        writable=table.choice("access", ("r", "w", "rw"), "r") in ("rw", "w"),
        length=table.integer("length", 1),
    )
    if register.length < 1:
        raise table.error("length", "must be 1 or more (values)")
    table.done()
    return register
