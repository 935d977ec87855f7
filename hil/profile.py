"""Unit profiles (TOML): unit type, limits, excitation settings, tolerances, simulated truth."""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hil.config import ConfigTable, builtin_fixture, read_toml
from hil.errors import ProfileError
from hil.motion import Limits
from plant_sim.firmware import Firmware, firmware_from_table
from plant_sim.params import PlantParams, plant_from_table

DEFAULT_PROFILE = "demo_gimbal_elevation"
DIRECTIONS = ("higher", "lower")
"""A measurement's optional ``direction``: which way is better."""


@dataclass(frozen=True, slots=True, kw_only=True)
class MeasurementSpec:
    """A declared measurement: acceptance limits around a nominal value.

    ``marginal_fraction``: the part of the distance from the nominal to each limit, next to
    that limit, in which a value is MARGINAL; ``accuracy_rel`` is the largest error the
    method claims on validation data (the project's tests hold it to it; not part of the
    uncertainty); ``allowance_rel`` is a hand-set allowance for physics the simulator lacks,
    a named rectangular Type B line of the budget when given. ``direction`` (``"higher"``
    or ``"lower"``): which way is better, for ``gimbal-hil compare``; ``None`` for a
    result without one (mechanics: a change is CHANGED, neither better nor worse).
    """

    name: str
    unit: str
    nominal: float
    lower_limit: float
    upper_limit: float
    marginal_fraction: float = 0.1
    accuracy_rel: float | None = None
    allowance_rel: float | None = None
    description: str = ""
    direction: str | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class UnitProfile:
    source: str
    sha256: str
    unit_type: str
    axis: str
    limits: Limits
    sample_rate_hz: float
    plant: PlantParams | None
    protocols: Mapping[str, Mapping[str, Any]]
    measurements: Mapping[str, MeasurementSpec]
    unit: Mapping[str, Any] = field(default_factory=dict)
    raw: Mapping[str, Any] = field(default_factory=dict)
    firmware: Firmware = field(default_factory=Firmware)  # the [firmware] table (or defaults)

    def protocol(self, name: str) -> Mapping[str, Any]:
        """Settings of one protocol; a clear error when the profile lacks them."""
        try:
            return self.protocols[name]
        except KeyError:
            raise ProfileError(f"no [protocols.{name}] table", source=self.source) from None

    def settings(self, name: str) -> ConfigTable:
        """Typed reader of one protocol's settings; its ``done()`` refuses unknown keys."""
        return ConfigTable(self.protocol(name), table=f"[protocols.{name}]", source=self.source)

    def measurement(self, name: str) -> MeasurementSpec:
        try:
            return self.measurements[name]
        except KeyError:
            raise ProfileError(f"no [measurements.{name}] table", source=self.source) from None


def builtin_profile_path(name: str = DEFAULT_PROFILE) -> Path:
    """Path of a profile shipped in ``fixtures/``."""
    path = builtin_fixture(f"{name}.toml")
    if not path.is_file():
        raise ProfileError(f"no built-in profile named '{name}'", source=str(path.parent))
    return path


def resolve_profile_path(name_or_path: str | Path | None) -> Path:
    """A file path as given, else a built-in profile name, else the default demo unit."""
    if name_or_path is None:
        return builtin_profile_path()
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise ProfileError("profile file not found", source=str(path))
        return path
    return builtin_profile_path(str(name_or_path))


def load_profile(name_or_path: str | Path | None = None) -> UnitProfile:
    """Read and validate a unit profile.

    Raises
    ------
    ProfileError
        Naming the file, the table and the key: a missing or unknown key, a wrong type, a
        value out of range.
    """
    path = resolve_profile_path(name_or_path)
    data, payload = read_toml(path)
    return profile_from_mapping(data, source=str(path), sha256=hashlib.sha256(payload).hexdigest())


def profile_from_mapping(data: Mapping[str, Any], *, source: str, sha256: str = "") -> UnitProfile:
    """Build a :class:`UnitProfile` from a parsed document; every table but the protocols'
    is checked here (each protocol checks its own table when it reads its settings)."""
    document = ConfigTable.root(data, source=source)
    unit = document.table_at("unit")
    unit_type = unit.string("type", "unknown")
    axis = unit.string("axis", "unknown")
    unit.string("description", "")
    unit.choice("axis_kind", ("rotary", "linear"), "rotary")
    for key in ("rated_torque_nm", "mass_kg", "kv_rpm_per_v"):
        if key in unit:
            unit.positive(key)
    unit.done()
    limits = _limits(document.table_at("limits"))
    drive = document.table_at("drive")
    sample_rate_hz = drive.positive("sample_rate_hz")
    drive.done()
    plant = plant_from_table(document.table_at("plant")) if "plant" in document else None
    firmware = firmware_from_table(document.table_at("firmware", required=False))
    protocols = {name: table.values for name, table in document.tables("protocols").items()}
    measurements = {
        name: _measurement(name, table) for name, table in document.tables("measurements").items()
    }
    document.done()
    return UnitProfile(
        source=source,
        sha256=sha256,
        unit_type=unit_type,
        axis=axis,
        limits=limits,
        sample_rate_hz=sample_rate_hz,
        plant=plant,
        firmware=firmware,
        protocols=protocols,
        measurements=measurements,
        unit=dict(unit.values),
        raw=dict(data),
    )


def _limits(table: ConfigTable) -> Limits:
    limits = Limits(
        velocity_rad_s=table.positive("velocity_rad_s"),
        torque_nm=table.positive("torque_nm"),
        travel_min_rad=table.number("travel_min_rad"),
        travel_max_rad=table.number("travel_max_rad"),
    )
    table.done()
    if limits.travel_min_rad >= limits.travel_max_rad:
        raise table.error("travel_min_rad", "must be below travel_max_rad")
    return limits


def _measurement(name: str, table: ConfigTable) -> MeasurementSpec:
    """Limits as ``lower``/``upper`` or as ``tolerance_pct`` around ``nominal``."""
    nominal = table.number("nominal")
    if "tolerance_pct" in table:
        if "lower" in table or "upper" in table:
            raise table.error("tolerance_pct", "give either tolerance_pct or lower/upper")
        half = abs(nominal) * table.non_negative("tolerance_pct") / 100.0
        lower, upper = nominal - half, nominal + half
    elif "lower" in table and "upper" in table:
        lower, upper = table.number("lower"), table.number("upper")
    else:
        raise ProfileError(
            f"{table.table} needs 'tolerance_pct' or both 'lower' and 'upper'", source=table.source
        )
    if not lower < upper:
        raise table.error("upper", f"lower limit {lower} is not below upper limit {upper}")
    accuracy = table.non_negative("accuracy_pct") if "accuracy_pct" in table else None
    allowance = table.non_negative("allowance_pct") if "allowance_pct" in table else None
    spec = MeasurementSpec(
        name=name,
        unit=table.string("unit", ""),
        nominal=nominal,
        lower_limit=lower,
        upper_limit=upper,
        marginal_fraction=table.non_negative("marginal_pct", 10.0) / 100.0,
        accuracy_rel=None if accuracy is None else accuracy / 100.0,
        allowance_rel=None if allowance is None else allowance / 100.0,
        description=table.string("description", ""),
        direction=table.choice("direction", DIRECTIONS) if "direction" in table else None,
    )
    table.done()
    return spec
