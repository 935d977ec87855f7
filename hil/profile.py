"""Unit profiles (TOML): unit type, limits, excitation settings, tolerances, simulated truth."""

from __future__ import annotations

import hashlib
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import fixtures
from hil.drives.base import Limits
from hil.errors import ProfileError
from plant_sim.params import PlantParams, plant_from_mapping

DEFAULT_PROFILE = "demo_gimbal_elevation"
FIXTURES_DIR = Path(fixtures.__file__).parent


@dataclass(frozen=True, slots=True, kw_only=True)
class MeasurementSpec:
    """A declared measurement: acceptance limits around a nominal value.

    ``marginal_fraction``: the part of the distance from the nominal to each limit, next to
    that limit, in which a value is MARGINAL; ``accuracy_rel`` is what the method claims
    (tests hold it to it).
    """

    name: str
    unit: str
    nominal: float
    lower_limit: float
    upper_limit: float
    marginal_fraction: float = 0.1
    accuracy_rel: float | None = None
    description: str = ""


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

    def protocol(self, name: str) -> Mapping[str, Any]:
        """Settings of one protocol; a clear error when the profile lacks them."""
        try:
            return self.protocols[name]
        except KeyError:
            raise ProfileError(f"no [protocols.{name}] table", source=self.source) from None

    def measurement(self, name: str) -> MeasurementSpec:
        try:
            return self.measurements[name]
        except KeyError:
            raise ProfileError(f"no [measurements.{name}] table", source=self.source) from None


def builtin_profile_path(name: str = DEFAULT_PROFILE) -> Path:
    """Path of a profile shipped in ``fixtures/``."""
    path = FIXTURES_DIR / f"{name}.toml"
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
    """Read and validate a unit profile. Raises :class:`ProfileError` naming file and key."""
    path = resolve_profile_path(name_or_path)
    source = str(path)
    payload = path.read_bytes()
    try:
        data = tomllib.loads(payload.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ProfileError(f"not valid TOML: {exc}", source=source) from exc
    return profile_from_mapping(data, source=source, sha256=hashlib.sha256(payload).hexdigest())


def profile_from_mapping(data: Mapping[str, Any], *, source: str, sha256: str = "") -> UnitProfile:
    unit = _table(data, "unit", source)
    limits_table = _table(data, "limits", source)
    drive = _table(data, "drive", source)
    try:
        limits = Limits(
            velocity_rad_s=_positive(limits_table, "velocity_rad_s", f"{source} [limits]"),
            torque_nm=_positive(limits_table, "torque_nm", f"{source} [limits]"),
            travel_min_rad=_number(limits_table, "travel_min_rad", f"{source} [limits]"),
            travel_max_rad=_number(limits_table, "travel_max_rad", f"{source} [limits]"),
        )
    except KeyError as exc:
        raise ProfileError(f"[limits] lacks {exc}", source=source) from exc
    if limits.travel_min_rad >= limits.travel_max_rad:
        raise ProfileError("[limits] travel_min_rad must be below travel_max_rad", source=source)
    plant = (
        plant_from_mapping(data["plant"], source=f"{source} [plant]") if "plant" in data else None
    )
    measurements = {
        name: _measurement(name, spec, f"{source} [measurements.{name}]")
        for name, spec in _table(data, "measurements", source).items()
    }
    return UnitProfile(
        source=source,
        sha256=sha256,
        unit_type=str(unit.get("type", "unknown")),
        axis=str(unit.get("axis", "unknown")),
        limits=limits,
        sample_rate_hz=_positive(drive, "sample_rate_hz", f"{source} [drive]"),
        plant=plant,
        protocols=dict(data.get("protocols", {})),
        measurements=measurements,
        unit=dict(unit),
        raw=dict(data),
    )


def _table(data: Mapping[str, Any], key: str, source: str) -> Mapping[str, Any]:
    value = data.get(key)
    if not isinstance(value, Mapping):
        raise ProfileError(f"missing table [{key}]", source=source)
    return value


def _number(table: Mapping[str, Any], key: str, source: str) -> float:
    try:
        return float(table[key])
    except KeyError:
        raise ProfileError(f"missing key '{key}'", source=source) from None
    except (TypeError, ValueError) as exc:
        raise ProfileError(f"'{key}' must be a number, got {table[key]!r}", source=source) from exc


def _positive(table: Mapping[str, Any], key: str, source: str) -> float:
    if key not in table:
        raise ProfileError(f"missing key '{key}'", source=source)
    value = _number(table, key, source)
    if not (math.isfinite(value) and value > 0):
        raise ProfileError(f"'{key}' must be a positive number, got {table[key]!r}", source=source)
    return value


def _measurement(name: str, spec: Mapping[str, Any], source: str) -> MeasurementSpec:
    """Limits as ``lower``/``upper`` or as ``tolerance_pct`` around ``nominal``."""
    if "nominal" not in spec:
        raise ProfileError("missing key 'nominal'", source=source)
    nominal = _number(spec, "nominal", source)
    if "tolerance_pct" in spec:
        half = abs(nominal) * _number(spec, "tolerance_pct", source) / 100.0
        lower, upper = nominal - half, nominal + half
    elif "lower" in spec and "upper" in spec:
        lower, upper = _number(spec, "lower", source), _number(spec, "upper", source)
    else:
        raise ProfileError("needs 'tolerance_pct' or both 'lower' and 'upper'", source=source)
    if not lower < upper:
        raise ProfileError(f"lower limit {lower} is not below upper limit {upper}", source=source)
    accuracy = spec.get("accuracy_pct")
    return MeasurementSpec(
        name=name,
        unit=str(spec.get("unit", "")),
        nominal=nominal,
        lower_limit=lower,
        upper_limit=upper,
        marginal_fraction=float(spec.get("marginal_pct", 10.0)) / 100.0,
        accuracy_rel=None if accuracy is None else float(accuracy) / 100.0,
        description=str(spec.get("description", "")),
    )
