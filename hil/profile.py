"""Unit profiles (TOML): unit type, limits, excitation settings, tolerances, simulated truth."""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hil.config import ConfigTable, Plausible, builtin_fixture, read_toml
from hil.errors import ProfileError
from hil.motion import Limits
from plant_sim.firmware import Firmware, firmware_from_table
from plant_sim.params import PlantParams, plant_from_table

DEFAULT_PROFILE = "demo_gimbal_elevation"
DIRECTIONS = ("higher", "lower")
"""A measurement's optional ``direction``: which way is better."""

# -- physically plausible ranges, checked as each setting is read (issue 26, item 14) --
TRAVEL_RAD = 20 * math.pi  # ten turns: beyond, no gimbal axis is calibrated
LIMIT_RANGES = {
    "velocity_rad_s": Plausible(0.0, 100.0, "rad/s", low_open=True),
    "torque_nm": Plausible(0.0, 1000.0, "N·m", low_open=True),
    "travel_min_rad": Plausible(-TRAVEL_RAD, TRAVEL_RAD, "rad"),
    "travel_max_rad": Plausible(-TRAVEL_RAD, TRAVEL_RAD, "rad"),
}
DRIVE_RANGES = {"sample_rate_hz": Plausible(100.0, 100_000.0, "Hz")}
PLANT_RANGES = {
    "inertia_kg_m2": Plausible(0.0, 100.0, "kg·m²", low_open=True),
    "encoder_counts_per_rev": Plausible(0, 2**31, "counts per revolution"),  # 0: ideal
    "stribeck_velocity_rad_s": Plausible(0.0, 10.0, "rad/s", low_open=True),
    "torque_limit_nm": Plausible(0.0, 1000.0, "N·m", low_open=True),
    "torque_constant_nm_a": Plausible(0.0, 100.0, "N·m/A", low_open=True),
}
_NON_NEGATIVE_RAD = Plausible(0.0, TRAVEL_RAD, "rad")
PROTOCOL_RANGES = {
    # whole numbers of periods, blocks, bins, ...
    "periods": Plausible(2, 100_000, "periods"),
    "settle_periods": Plausible(0, 10_000, "periods"),
    "min_periods": Plausible(1, 10_000, "periods"),
    "blocks": Plausible(1, 1000, "blocks"),
    "bins": Plausible(2, 100_000, "bins"),
    "points": Plausible(2, 10_000, "points"),
    "lines": Plausible(1, 10_000, "lines"),
    "harmonics": Plausible(1, 1000, "harmonics"),
    "levels": Plausible(2, 10_000, "levels"),
    "min_order": Plausible(1, 100_000),
    "max_order": Plausible(1, 100_000),
    "min_samples_per_pass": Plausible(1, 100_000_000, "samples"),
    "max_runs": Plausible(1, 1000, "runs"),
    # fractions, rates, distances that cannot be negative
    "peak_torque_fraction": Plausible(0.0, 1.0, "of the torque limit", low_open=True),
    "stop_at_u_fraction": Plausible(0.0, 10.0, low_open=True),
    "min_sample_rate_hz": Plausible(0.0, 100_000.0, "Hz", low_open=True),
    "skip_rad": _NON_NEGATIVE_RAD,
    "exclude_rad": _NON_NEGATIVE_RAD,
    "margin_rad": _NON_NEGATIVE_RAD,
    "turnaround_rad": _NON_NEGATIVE_RAD,
    "probe_rad": Plausible(0.0, TRAVEL_RAD, "rad", low_open=True),
    "step_travel_rad": Plausible(0.0, TRAVEL_RAD, "rad", low_open=True),
}
PROTOCOL_UNIT_RANGES = (  # any other protocol key, by its unit (longest suffix first)
    ("_hz", Plausible(0.0, 5000.0, "Hz", low_open=True)),
    ("_rad_s", Plausible(0.0, 100.0, "rad/s", low_open=True)),
    ("_rad", Plausible(-TRAVEL_RAD, TRAVEL_RAD, "rad")),
    ("_s", Plausible(0.0, 600.0, "s")),
)


def protocol_range(key: str) -> Plausible | None:
    """The plausible range of a ``[protocols.*]`` setting: by its name, else by its unit."""
    if key in PROTOCOL_RANGES:
        return PROTOCOL_RANGES[key]
    return next((r for suffix, r in PROTOCOL_UNIT_RANGES if key.endswith(suffix)), None)


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
    required: bool = True  # not measured (skipped, deselected) → the run is INCOMPLETE


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
        return ConfigTable(self.protocol(name), table=f"[protocols.{name}]",
                           source=self.source).with_ranges(protocol_range)

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
    limits = _limits(document.table_at("limits").with_ranges(LIMIT_RANGES.get))
    drive = document.table_at("drive").with_ranges(DRIVE_RANGES.get)
    sample_rate_hz = drive.positive("sample_rate_hz")
    drive.done()
    plant = (plant_from_table(document.table_at("plant").with_ranges(PLANT_RANGES.get))
             if "plant" in document else None)
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
        required=table.boolean("required", True),
    )
    table.done()
    return spec
