"""CANopen object maps (TOML, one per drive model): where a drive keeps each value the
harness uses beyond the CiA 402 standard objects, how it is coded, and the drive's
conventions that the client cannot read from it.

Nothing vendor-specific is addressed by index alone: a role is either given here (index,
subindex, type, scale) or ``"absent"``, and bring-up checks each given one against the
drive (:func:`check_objects`) before any motion. Roles:

- ``torque_mean``: the torque averaged over the SYNC period (PDO-mappable, signed).
- ``control_period``: the drive's control-loop period (unsigned; ``seconds_per_count``).
- ``recorder`` / ``waveform``: a trace recorder and waveform player in the gimbal-hil
  layout (``hil.drives.cia402.acquire``); a vendor recorder of another layout is absent
  here until an adapter reads it.
- ``compensation_table``: the cogging / K_t ripple table (``pack_harmonics`` layout).

Conventions: ``position_latch`` (``"control_period_before_sync"``: the position of the
last control period's start, as the torque of that period; ``"sync"``; ``"unknown"``),
``torque_reports`` (what the torque objects hold: ``"demand"``, ``"measured"``,
``"unknown"``), ``interpolation_codes`` (0x60C0 value → ``"linear"`` / ``"hold"``), and
``heartbeat_at_power_on``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from hil.config import ConfigTable, builtin_fixture, read_toml
from hil.errors import ProfileError

#: CANopen data types a role may have: DS301 code, struct code
DATA_TYPES: Mapping[str, tuple[int, str]] = {
    "INTEGER16": (0x0003, "h"),
    "INTEGER32": (0x0004, "i"),
    "UNSIGNED16": (0x0006, "H"),
    "UNSIGNED32": (0x0007, "I"),
}
POSITION_LATCHES = ("control_period_before_sync", "sync", "unknown")
TORQUE_REPORTS = ("demand", "measured", "unknown")
INTERPOLATIONS = ("linear", "hold")
ABSENT = "absent"
INCREMENTS = "increments"  # velocity in position increments per second
MAPS_DIR = "canopen_maps"
GENERIC_MAP = "cia402_generic"  # a station that names no map


@dataclass(frozen=True, slots=True, kw_only=True)
class ObjectRef:
    """One object of the drive: where, what type, and its scale (``per_unit``: counts per
    rated torque for a torque, per second for a period)."""

    role: str
    index: int
    subindex: int
    data_type: str
    per_unit: float

    @property
    def code(self) -> int:
        """The DS301 data type code."""
        return DATA_TYPES[self.data_type][0]

    @property
    def struct_code(self) -> str:
        return DATA_TYPES[self.data_type][1]

    @property
    def bits(self) -> int:
        return 16 if self.data_type.endswith("16") else 32

    def __str__(self) -> str:
        return f"{self.role} 0x{self.index:04X}:{self.subindex:02X} {self.data_type}"


@dataclass(frozen=True, slots=True, kw_only=True)
class ObjectMap:
    """A drive model's objects and conventions (see the module docstring)."""

    name: str
    document: str
    source: str
    torque_mean: ObjectRef | None = None
    control_period: ObjectRef | None = None
    recorder_index: int | None = None
    waveform_index: int | None = None
    compensation_index: int | None = None
    rated_torque_per_nm: float = 1e3  # 0x6076 counts per N·m (CiA 402: mN·m)
    rated_current_per_a: float = 1e3  # 0x6075 counts per A (CiA 402: mA)
    velocity_per_rad_s: float | None = None  # 0x606C/0x60FF per rad/s; None: increments/s
    position_latch: str = "unknown"
    torque_reports: str = "unknown"
    interpolation_codes: Mapping[int, str] = field(default_factory=lambda: {0: "linear"})
    heartbeat_at_power_on: bool = False

    @property
    def has_recorder(self) -> bool:
        return self.recorder_index is not None and self.waveform_index is not None

    def conventions(self) -> dict[str, str]:
        """What a recording states about the drive's conventions (and the map's name)."""
        return {"object_map": self.name, "position_latch": self.position_latch,
                "torque_reports": self.torque_reports}

    def objects(self) -> list[ObjectRef]:
        """Every single-variable role the map gives."""
        return [ref for ref in (self.torque_mean, self.control_period) if ref is not None]


def load_object_map(name_or_path: str | Path, *, base_dir: Path | None = None) -> ObjectMap:
    """Read an object map: a path (relative to ``base_dir``), or a shipped map's name
    (``fixtures/canopen_maps/NAME.toml``).

    Raises
    ------
    ProfileError
        No such file or map, or a missing, mistyped or unknown key (one line naming the
        file, table and key).
    """
    path = _find(str(name_or_path), base_dir)
    document, _ = read_toml(path)
    root = ConfigTable.root(document, source=str(path))
    top = root.table_at("map")
    objects = root.table_at("objects")
    units = root.table_at("units")
    velocity = units.values.get("velocity_per_rad_s")
    conventions = root.table_at("conventions")
    codes = conventions.table_at("interpolation_codes", required=False)
    interpolation = {_code(codes, key): codes.choice(key, INTERPOLATIONS)
                     for key in list(codes.values)} or {0: "linear"}
    result = ObjectMap(
        name=top.string("name"),
        document=top.string("document"),
        source=str(path),
        torque_mean=_ref(objects, "torque_mean"),
        control_period=_ref(objects, "control_period"),
        recorder_index=_index(objects, "recorder"),
        waveform_index=_index(objects, "waveform"),
        compensation_index=_index(objects, "compensation_table"),
        rated_torque_per_nm=units.positive("rated_torque_per_nm"),
        rated_current_per_a=units.positive("rated_current_per_a"),
        velocity_per_rad_s=None if velocity == INCREMENTS and units.string("velocity_per_rad_s")
        else units.positive("velocity_per_rad_s"),
        position_latch=conventions.choice("position_latch", POSITION_LATCHES),
        torque_reports=conventions.choice("torque_reports", TORQUE_REPORTS),
        interpolation_codes=interpolation,
        heartbeat_at_power_on=conventions.boolean("heartbeat_at_power_on"),
    )
    if (result.recorder_index is None) != (result.waveform_index is None):
        raise objects.error("recorder", "the recorder and the waveform table come together "
                                        "(both given, or both \"absent\")")
    top.done()
    objects.done()
    units.done()
    conventions.done()
    root.done()
    return result


def shipped_maps() -> list[str]:
    """The names of the maps shipped in ``fixtures/canopen_maps``."""
    return sorted(p.stem for p in builtin_fixture(MAPS_DIR).glob("*.toml"))


def _find(name: str, base_dir: Path | None) -> Path:
    candidate = Path(name)
    if not candidate.is_absolute() and base_dir is not None:
        candidate = base_dir / candidate
    if candidate.is_file():
        return candidate
    shipped = builtin_fixture(MAPS_DIR) / f"{Path(name).stem}.toml"
    if shipped.is_file():
        return shipped
    raise ProfileError(f"object map '{name}' not found (a file, or one of: "
                       f"{', '.join(shipped_maps())})")


def _code(table: ConfigTable, key: str) -> int:
    try:
        return int(key)
    except ValueError:
        raise table.error(key, "an interpolation code is an integer (0x60C0's value)") from None


def _absent(table: ConfigTable, key: str) -> bool:
    if key not in table:
        raise table.error(key, f"missing: give it, or \"{ABSENT}\"")
    return table.values.get(key) == ABSENT


def _index(table: ConfigTable, key: str) -> int | None:
    if _absent(table, key):
        table.string(key)
        return None
    one = table.table_at(key)
    index = one.integer("index")
    one.done()
    return index


def _ref(table: ConfigTable, key: str) -> ObjectRef | None:
    if _absent(table, key):
        table.string(key)
        return None
    one = table.table_at(key)
    ref = ObjectRef(role=key, index=one.integer("index"), subindex=one.integer("subindex"),
                    data_type=one.choice("type", tuple(DATA_TYPES)),
                    per_unit=one.positive("per_unit"))
    one.done()
    return ref
