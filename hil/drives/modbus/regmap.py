"""Register maps (TOML, one per drive model): where each value lives and how it is coded."""

from __future__ import annotations

import struct
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from hil.errors import ProfileError

TYPES = {
    "int16": ("h", 1),
    "uint16": ("H", 1),
    "int32": ("i", 2),
    "uint32": ("I", 2),
    "float32": ("f", 2),
}
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
TORQUE_MEAN = "torque_mean"
TORQUE_MEAN_WINDOW = "torque_mean_window"


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

    @property
    def count(self) -> int:
        return TYPES[self.type][1]

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
            (self.registers[n].address, self.registers[n].address + self.registers[n].count)
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


def load_register_map(path: str | Path) -> RegisterMap:
    path = Path(path)
    source = str(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ProfileError(f"cannot read register map: {exc}", source=source) from exc
    device = data.get("device", {})
    byte_order = str(device.get("byte_order", "big"))
    word_order = str(device.get("word_order", "big"))
    registers: dict[str, Register] = {}
    for name, spec in data.get("registers", {}).items():
        registers[name] = _register(name, spec, byte_order, word_order, source)
    missing = [name for name in REQUIRED if name not in registers]
    if missing:
        raise ProfileError(f"register map lacks {', '.join(missing)}", source=source)
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
    if SETPOINT_INTERPOLATION in registers and not registers[SETPOINT_INTERPOLATION].writable:
        raise ProfileError(
            f"register '{SETPOINT_INTERPOLATION}' must be writable (access = \"rw\")",
            source=f"{source} [registers.{SETPOINT_INTERPOLATION}]",
        )
    control_period = device.get("control_period_s")
    if control_period is not None and not (
        isinstance(control_period, int | float) and control_period > 0
    ):
        raise ProfileError(
            f"[device] control_period_s must be a positive number, got {control_period!r}",
            source=source,
        )
    bits = data.get("bits", {})
    return RegisterMap(
        source=source,
        model=str(device.get("model", path.stem)),
        registers=registers,
        max_registers_per_read=int(device.get("max_registers_per_read", 125)),
        frame_gap_s=float(device.get("frame_gap_s", 0.0)),
        control_period_s=None if control_period is None else float(control_period),
        control_bits={"enable": 0, "quick_stop": 1, "fault_reset": 2, **bits.get("control", {})},
        status_bits={"enabled": 0, "fault": 1, "quick_stop_active": 2, **bits.get("status", {})},
        modes={"torque": 1, "velocity": 2, "position": 3, **data.get("modes", {})},
    )


def _register(
    name: str, spec: Mapping[str, Any], byte_order: str, word_order: str, source: str
) -> Register:
    where = f"{source} [registers.{name}]"
    if not isinstance(spec, Mapping) or "address" not in spec or "type" not in spec:
        raise ProfileError("needs 'address' and 'type'", source=where)
    kind = str(spec["type"])
    if kind not in TYPES:
        raise ProfileError(f"type must be one of {', '.join(TYPES)}, got '{kind}'", source=where)
    access = str(spec.get("access", "r"))
    if access not in ("r", "rw", "w"):
        raise ProfileError("access must be 'r', 'w' or 'rw'", source=where)
    scale = float(spec.get("scale", 1.0))
    if scale == 0:
        raise ProfileError("scale must not be 0", source=where)
    order = str(spec.get("word_order", word_order))
    if order not in ("big", "little") or byte_order not in ("big", "little"):
        raise ProfileError("byte/word order must be 'big' or 'little'", source=where)
    return Register(
        name=name,
        address=int(spec["address"]),
        type=kind,
        word_order=order,
        byte_order=byte_order,
        scale=scale,
        unit=str(spec.get("unit", "")),
        writable=access in ("rw", "w"),
    )
