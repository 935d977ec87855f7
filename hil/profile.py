"""Unit profiles (TOML): unit type, limits, excitation settings, tolerances, simulated truth."""

from __future__ import annotations

import hashlib
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gimbal_hil_fixtures

from hil.errors import ProfileError
from hil.motion import Limits
from plant_sim.params import PlantParams, plant_from_mapping

DEFAULT_PROFILE = "demo_gimbal_elevation"
FIXTURES_DIR = Path(gimbal_hil_fixtures.__file__).parent


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

    def settings(self, name: str) -> ProtocolSettings:
        """Typed reader of one protocol's settings (see :class:`ProtocolSettings`)."""
        return ProtocolSettings(self.protocol(name), table=f"[protocols.{name}]",
                                source=self.source)

    def measurement(self, name: str) -> MeasurementSpec:
        try:
            return self.measurements[name]
        except KeyError:
            raise ProfileError(f"no [measurements.{name}] table", source=self.source) from None


class ProtocolSettings:
    """Reads a ``[protocols.NAME]`` table: values converted with a :class:`ProfileError` that
    names file, table and key; :meth:`done` refuses keys nobody read (a typo would otherwise
    silently fall back to a default)."""

    def __init__(self, values: Mapping[str, Any], *, table: str, source: str) -> None:
        self._values = values
        self._table = table
        self._source = source
        self._read: set[str] = set()

    def _get(self, key: str, default: Any) -> Any:
        self._read.add(key)
        if key in self._values:
            return self._values[key]
        if default is None:
            raise ProfileError(f"{self._table} lacks '{key}'", source=self._source)
        return default

    def _error(self, key: str, what: str) -> ProfileError:
        value = self._values.get(key)
        return ProfileError(f"{self._table} '{key}' must be {what}, got {value!r}",
                            source=self._source)

    def number(self, key: str, default: float | None = None) -> float:
        value = self._get(key, default)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self._error(key, "a number")
        if not math.isfinite(value):
            raise self._error(key, "finite")
        return float(value)

    def integer(self, key: str, default: int | None = None) -> int:
        value = self._get(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self._error(key, "an integer")
        return value

    def numbers(self, key: str, *, count: int | None = None) -> tuple[float, ...]:
        value = self._get(key, None)
        if not isinstance(value, list) or not value or any(
            isinstance(v, bool) or not isinstance(v, int | float) for v in value
        ):
            raise self._error(key, "a non-empty list of numbers")
        if count is not None and len(value) != count:
            raise self._error(key, f"a list of {count} numbers")
        return tuple(float(v) for v in value)

    def choice(self, key: str, options: tuple[str, ...], default: str) -> str:
        value = self._get(key, default)
        if value not in options:
            raise self._error(key, f"one of {', '.join(options)}")
        return str(value)

    def done(self) -> None:
        """Refuse keys that no reader asked for."""
        unknown = sorted(set(self._values) - self._read)
        if unknown:
            raise ProfileError(
                f"{self._table} has unknown setting(s) {', '.join(map(repr, unknown))} "
                f"(known: {', '.join(sorted(self._read))})",
                source=self._source,
            )


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
