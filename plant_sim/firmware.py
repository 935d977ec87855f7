"""The drive's firmware: its controller settings, kept apart from the plant's physics.

A unit profile's ``[firmware]`` table. The simulator (and both emulators, which run it)
obeys it: the velocity PI and its velocity filter, the current loop's lag, extra samples
of delay between the torque command and the current loop, and two switches: ``feedforward``
(the drive adds the torque offset the master sends, i.e. the certificate's
``B·ω* + T_c·sgn(ω*)``) and ``cogging_compensation`` (the drive applies the compensation
table of ``cogging_compensation.json`` loaded into it).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any, Final

from hil.config import ConfigTable
from hil.errors import ProfileError

FIRMWARE_KEYS: Final = (
    "version",
    "velocity_kp_nm_s_rad",
    "velocity_ki_nm_rad",
    "velocity_filter_hz",
    "current_loop_time_constant_s",
    "command_delay_samples",
    "feedforward",
    "cogging_compensation",
)
"""The ``[firmware]`` keys (external tools write profiles with exactly these names)."""

MAX_DELAY_SAMPLES: Final = 64


@dataclass(frozen=True, slots=True, kw_only=True)
class Firmware:
    """The drive firmware's settings.

    Attributes
    ----------
    version : str
        Reported as the drive's firmware version (on the certificate).
    velocity_kp_nm_s_rad, velocity_ki_nm_rad : float
        The velocity PI: ``T = Kp·e + Ki·∫e dt`` with ``e = ω* − ω̂``.
    velocity_filter_hz : float
        First-order filter of the velocity estimate (0: raw position difference).
    current_loop_time_constant_s : float
        First-order lag of the current (torque) loop.
    command_delay_samples : int
        Extra control periods between the torque command and the current loop.
    feedforward : bool
        The drive adds the torque offset it is sent (CiA 402 0x60B2) to its command.
    cogging_compensation : bool
        The drive applies the cogging / K_t ripple compensation table loaded into it.
    """

    version: str = "sim-1.0"
    velocity_kp_nm_s_rad: float = 0.05
    velocity_ki_nm_rad: float = 1.0
    velocity_filter_hz: float = 0.0
    current_loop_time_constant_s: float = 0.0
    command_delay_samples: int = 0
    feedforward: bool = False
    cogging_compensation: bool = False

    def __post_init__(self) -> None:
        for name in ("velocity_kp_nm_s_rad", "velocity_ki_nm_rad", "velocity_filter_hz",
                     "current_loop_time_constant_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ProfileError(f"'{name}' must be finite and >= 0, got {value}")
        if not 0 <= self.command_delay_samples <= MAX_DELAY_SAMPLES:
            raise ProfileError(f"'command_delay_samples' must be 0..{MAX_DELAY_SAMPLES}, "
                               f"got {self.command_delay_samples}")
        if not self.version.strip():
            raise ProfileError("'version' must not be empty")

    def with_changes(self, **changes: Any) -> Firmware:
        """A copy with ``changes`` applied (validated again)."""
        return replace(self, **changes)


def firmware_from_table(table: ConfigTable) -> Firmware:
    """Build :class:`Firmware` from a ``[firmware]`` table (absent keys keep the defaults).

    Raises
    ------
    ProfileError
        An unknown key, a wrong type or a value out of range, naming file, table and key.
    """
    kwargs: dict[str, Any] = {}
    for f in fields(Firmware):
        if f.name not in table:
            continue
        if f.name == "version":
            kwargs[f.name] = table.string(f.name)
        elif f.name in ("feedforward", "cogging_compensation"):
            kwargs[f.name] = table.boolean(f.name)
        elif f.name == "command_delay_samples":
            kwargs[f.name] = table.integer(f.name)
        else:
            kwargs[f.name] = table.number(f.name)
    for key in FIRMWARE_KEYS:
        if key not in table:
            table.number(key, 0.0)  # absent: marks the key known, for done()'s typo hint
    table.done()
    try:
        return Firmware(**kwargs)
    except ProfileError as exc:
        raise ProfileError(f"{table.table} {exc.message}", source=table.source) from None


def firmware_from_mapping(data: Mapping[str, Any], *, source: str = "[firmware]") -> Firmware:
    """Build :class:`Firmware` from a parsed ``[firmware]`` table."""
    return firmware_from_table(ConfigTable(data, table="[firmware]", source=source))


def firmware_to_mapping(firmware: Firmware) -> dict[str, Any]:
    """Every key of :class:`Firmware`, TOML-ready."""
    return {f.name: getattr(firmware, f.name) for f in fields(Firmware)}


def refuse_moved_keys(plant: ConfigTable) -> None:
    """One clear error when a ``[plant]`` table still holds a firmware setting.

    Raises
    ------
    ProfileError
        Naming the key(s) and where they moved.
    """
    moved = [key for key in FIRMWARE_KEYS if key in plant]
    if moved:
        raise ProfileError(
            f"[plant] holds {', '.join(repr(k) for k in moved)}: the drive's controller "
            "settings moved to the [firmware] table (keys: " + ", ".join(FIRMWARE_KEYS) + ")",
            source=plant.source,
        )
