"""A station's test equipment besides the drive, declared in its station file: a shaft
torque transducer (read over Modbus TCP from its amplifier) and a locked-rotor fixture
(a clamp engaged by one of the drive's digital outputs). Together they let the torque
constant K_t be measured on a field-bus station.

``[torque_transducer]``: ``host``, ``port``, ``unit_id``, ``address`` (the input register
of a float32, high word first), ``scale_nm`` (N·m per unit read: 1 for an amplifier that
reports N·m), ``zero_nm`` (subtracted), ``poll_period_s``, and its own calibration:
``certificate`` (the certificate's number) and ``relative_uncertainty_pct`` (the expanded
uncertainty of its sensitivity, ``coverage_factor`` 2 unless stated), which enters K_t's
budget as a Type B line.

``[locked_rotor]``: ``output_bit`` (the drive's digital output, CiA 402 0x60FE:01 or the
register map's ``digital_outputs``), and the check move that confirms the clamp holds
before any current is driven against it: ``check_torque_nm`` for ``check_s``, the axis
moving less than ``tolerance_rad``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hil.config import ConfigTable
from hil.drives.base import Capability


@dataclass(frozen=True, slots=True, kw_only=True)
class TorqueTransducer:
    """A shaft torque transducer's amplifier on Modbus TCP (module docstring)."""

    source: str
    host: str
    port: int
    unit_id: int
    address: int
    scale_nm: float
    zero_nm: float
    poll_period_s: float
    certificate: str
    relative_uncertainty_pct: float
    coverage_factor: float

    @property
    def relative_standard_uncertainty(self) -> float:
        """u of its sensitivity, relative (the certificate's U over its k)."""
        return self.relative_uncertainty_pct / 100.0 / self.coverage_factor

    @property
    def where(self) -> str:
        return f"torque transducer modbus tcp {self.host}:{self.port} unit {self.unit_id}"


@dataclass(frozen=True, slots=True, kw_only=True)
class LockedRotor:
    """A clamp engaged by a drive output, and its check move (module docstring)."""

    output_bit: int
    check_torque_nm: float
    check_s: float
    tolerance_rad: float


@dataclass(frozen=True, slots=True)
class Equipment:
    """What the station has besides the drive."""

    torque_transducer: TorqueTransducer | None = None
    locked_rotor: LockedRotor | None = None

    def capabilities(self) -> frozenset[Capability]:
        """The capabilities this equipment gives a drive (both, for K_t)."""
        found = set()
        if self.torque_transducer is not None:
            found.add(Capability.TORQUE_SENSOR)
        if self.locked_rotor is not None:
            found.add(Capability.LOCKED_ROTOR)
        return frozenset(found)


def sensor_fields(equipment: Equipment) -> dict[str, Any]:
    """The :class:`hil.drives.base.DriveInfo` fields of the station's torque sensor."""
    t = equipment.torque_transducer
    if t is None:
        return {}
    return {"torque_sensor": f"{t.where}, calibration certificate {t.certificate} "
                             f"(U = {t.relative_uncertainty_pct:g} %, k = {t.coverage_factor:g})",
            "torque_sensor_relative_u": t.relative_standard_uncertainty}


def read_equipment(document: ConfigTable) -> Equipment:
    """The ``[torque_transducer]`` and ``[locked_rotor]`` tables of a station file.

    Raises
    ------
    ProfileError
        A missing, mistyped or unknown key (one line naming file, table and key).
    """
    transducer = None
    if "torque_transducer" in document:
        table = document.table_at("torque_transducer")
        transducer = TorqueTransducer(
            source=table.source,
            host=table.string("host", "127.0.0.1"),
            port=table.integer("port", 502),
            unit_id=table.integer("unit_id", 1),
            address=table.integer("address", 0),
            scale_nm=table.positive("scale_nm", 1.0),
            zero_nm=table.number("zero_nm", 0.0),
            poll_period_s=table.positive("poll_period_s", 0.002),
            certificate=table.string("certificate"),
            relative_uncertainty_pct=table.non_negative("relative_uncertainty_pct"),
            coverage_factor=table.positive("coverage_factor", 2.0),
        )
        table.done()
    locked = None
    if "locked_rotor" in document:
        table = document.table_at("locked_rotor")
        bit = table.integer("output_bit")
        if not 0 <= bit <= 31:
            raise table.error("output_bit", f"must be 0..31, got {bit}")
        locked = LockedRotor(
            output_bit=bit,
            check_torque_nm=table.positive("check_torque_nm"),
            check_s=table.positive("check_s", 0.3),
            tolerance_rad=table.positive("tolerance_rad", 0.002),
        )
        table.done()
    return Equipment(torque_transducer=transducer, locked_rotor=locked)
