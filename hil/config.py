"""The one reader of TOML settings: unit profiles, station files, register maps, the plant.

Every table is read through a :class:`ConfigTable`: typed getters that refuse a wrong type
(a string where a number belongs, a bool where an integer belongs), and :meth:`~ConfigTable.done`,
which refuses every key nobody asked for, so a misspelt setting is an error naming the file,
the table and the key, never a silent default.
"""

from __future__ import annotations

import difflib
import hashlib
import math
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Final, TypeVar

from hil.errors import ProfileError

FIXTURES_PACKAGE: Final = "gimbal_hil_fixtures"

class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


REQUIRED: Final = _Required()
"""Default of a getter whose key must be present."""


def builtin_fixture(name: str) -> Path:
    """Path of a data file shipped with gimbal-hil (profiles, stations, EDS, register map)."""
    return Path(str(resources.files(FIXTURES_PACKAGE).joinpath(name)))


def read_toml(path: Path) -> tuple[dict[str, Any], bytes]:
    """Parse ``path``; the parsed document and the raw bytes (for a SHA-256).

    Raises
    ------
    ProfileError
        The file is missing, not UTF-8 or not valid TOML (naming the file).
    """
    try:
        payload = path.read_bytes()
    except OSError as exc:
        raise ProfileError(f"cannot read: {exc.strerror}", source=str(path)) from None
    try:  # a byte-order mark some editors write is not part of the document
        return tomllib.loads(payload.decode("utf-8").removeprefix("\ufeff")), payload
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ProfileError(f"not valid TOML: {exc}", source=str(path)) from None


Entry = TypeVar("Entry")


@dataclass(frozen=True, slots=True)
class Plausible:
    """A setting's physically plausible range: ``low`` (excluded with ``low_open``) to
    ``high``, in ``unit``; a value outside is refused at load, naming file, table and key."""

    low: float
    high: float
    unit: str = ""
    low_open: bool = False

    def problem(self, value: float) -> str | None:
        """What is wrong with ``value`` (``None``: plausible)."""
        unit = f" {self.unit}" if self.unit else ""
        if self.low_open and not value > self.low:
            return f"must be > {self.low:g}{unit}"
        if not value >= self.low:
            return f"must be ≥ {self.low:g}{unit}"
        if not value <= self.high:
            return f"must be ≤ {self.high:g}{unit}"
        return None


Ranges = Callable[[str], Plausible | None]
"""A table's plausible ranges by key (``None``: the key has none)."""


def read_results_by_axis(
    path: Path, entry: Callable[[str, ConfigTable], Entry]
) -> tuple[str, dict[str, dict[str, Entry]]]:
    """A map file of ``[results.AXIS.NAME]`` tables under a ``population`` string (the
    method-bias and repeatability maps): the SHA-256 of its bytes and ``entry(name, table)``
    by axis and name.

    Raises
    ------
    ProfileError
        A missing, mistyped or unknown key in any table, naming file, table and key.
    """
    document, payload = read_toml(path)
    root = ConfigTable.root(document, source=str(path))
    root.string("population")
    by_axis = {
        axis: {name: entry(name, table) for name, table in results.tables_here().items()}
        for axis, results in root.tables("results").items()
    }
    root.done()
    return hashlib.sha256(payload).hexdigest(), by_axis


class ConfigTable:
    """One TOML table of one file, read key by key.

    Parameters
    ----------
    values : Mapping
        The parsed table.
    table : str
        Its name as a person finds it in the file, e.g. ``"[limits]"``.
    source : str
        The file.
    """

    def __init__(self, values: Mapping[str, Any], *, table: str, source: str) -> None:
        self.values = values
        self.table = table
        self.source = source
        self._read: set[str] = set()
        self.ranges: Ranges | None = None

    def with_ranges(self, ranges: Ranges) -> ConfigTable:
        """This table, its numbers checked against ``ranges`` as they are read."""
        self.ranges = ranges
        return self

    def _plausible(self, key: str, value: float, item: int | None = None) -> None:
        plausible = self.ranges(key) if self.ranges is not None else None
        problem = plausible.problem(value) if plausible is not None else None
        if problem is not None:
            at = "" if item is None else f" (item {item + 1})"
            raise ProfileError(f"{self.table} {key} = {value:g}{at}: {problem}",
                               source=self.source)

    @classmethod
    def root(cls, document: Mapping[str, Any], *, source: str) -> ConfigTable:
        """The whole document as a table (its keys are the top-level tables)."""
        return cls(document, table="(top level)", source=source)

    def error(self, key: str, message: str) -> ProfileError:
        """A :class:`ProfileError` naming file, table and key."""
        return ProfileError(f"{self.table} '{key}': {message}", source=self.source)

    def __contains__(self, key: str) -> bool:
        return key in self.values

    def _get(self, key: str, default: Any) -> Any:
        self._read.add(key)
        if key in self.values:
            return self.values[key]
        if default is REQUIRED:
            raise ProfileError(f"{self.table} lacks '{key}'{self._found(key)}", source=self.source)
        return default

    def _found(self, missing: str) -> str:
        """A hint naming a present key that looks like a misspelling of ``missing``."""
        close = difflib.get_close_matches(missing, sorted(set(self.values) - self._read), n=1)
        return f" (found '{close[0]}': misspelt?)" if close else ""

    def _typed(self, key: str, default: Any, kind: type | tuple[type, ...], what: str) -> Any:
        value = self._get(key, default)
        if value is default and default is not REQUIRED:
            return value
        if isinstance(value, bool) and bool not in _as_tuple(kind):
            raise self.error(key, f"must be {what}, got {value!r}")
        if not isinstance(value, kind):
            raise self.error(key, f"must be {what}, got {value!r}")
        return value

    def number(self, key: str, default: float | _Required | None = REQUIRED) -> float:
        """A finite number (int or float in the file). ``default=None`` means required too,
        as the protocol settings have always read it."""
        value = self._typed(key, REQUIRED if default is None else default, (int, float),
                            "a number")
        if not math.isfinite(value):
            raise self.error(key, f"must be finite, got {value!r}")
        self._plausible(key, value)
        return float(value)

    def positive(self, key: str, default: float | _Required = REQUIRED) -> float:
        """A finite number above zero."""
        value = self.number(key, default)
        if not value > 0:
            raise self.error(key, f"must be above zero, got {value!r}")
        return value

    def optional_positive(self, key: str) -> float | None:
        """A finite number above zero, or ``None`` when the key is absent."""
        self._read.add(key)
        return self.positive(key) if key in self.values else None

    def non_negative(self, key: str, default: float | _Required = REQUIRED) -> float:
        """A finite number at or above zero."""
        value = self.number(key, default)
        if not value >= 0:
            raise self.error(key, f"must be zero or above, got {value!r}")
        return value

    def integer(self, key: str, default: int | _Required | None = REQUIRED) -> int:
        """An integer (a float such as ``2.0`` is refused)."""
        value: int = self._typed(key, REQUIRED if default is None else default, int,
                                 "an integer")
        self._plausible(key, value)
        return value

    def boolean(self, key: str, default: bool | _Required = REQUIRED) -> bool:
        """``true`` or ``false``."""
        value: bool = self._typed(key, default, bool, "true or false")
        return value

    def string(self, key: str, default: str | _Required = REQUIRED) -> str:
        """A string."""
        value: str = self._typed(key, default, str, "a string")
        return value

    def choice(self, key: str, options: tuple[str, ...], default: str | _Required = REQUIRED
               ) -> str:
        """One of ``options``."""
        value = self.string(key, default)
        if value not in options:
            raise self.error(key, f"must be one of {', '.join(options)}, got {value!r}")
        return value

    def numbers(self, key: str, *, count: int | None = None) -> tuple[float, ...]:
        """A non-empty list of finite numbers (``count`` of them when given)."""
        value = self._get(key, REQUIRED)
        if (
            not isinstance(value, list)
            or not value
            or any(isinstance(v, bool) or not isinstance(v, int | float) for v in value)
            or not all(math.isfinite(v) for v in value)
        ):
            raise self.error(key, f"must be a non-empty list of finite numbers, got {value!r}")
        if count is not None and len(value) != count:
            raise self.error(key, f"must be a list of {count} numbers, got {len(value)}")
        for item, number in enumerate(value):
            self._plausible(key, number, item)
        return tuple(float(v) for v in value)

    def table_at(self, key: str, *, required: bool = True) -> ConfigTable:
        """The sub-table ``key`` (``[parent.key]``); empty when optional and absent."""
        if required and key not in self.values:
            self._read.add(key)
            raise ProfileError(f"missing table {self._child(key)}{self._found(key)}",
                               source=self.source)
        value = self._get(key, {})
        if not isinstance(value, Mapping):
            raise self.error(key, f"must be a table, got {value!r}")
        return ConfigTable(value, table=self._child(key), source=self.source)

    def tables(self, key: str) -> dict[str, ConfigTable]:
        """The sub-tables of ``key`` by name (``[key.NAME]``); none when absent."""
        return self.table_at(key, required=False).tables_here()

    def tables_here(self) -> dict[str, ConfigTable]:
        """Every key of this table as a sub-table (``[this.NAME]``), by name."""
        return {name: self.table_at(name) for name in self.values}

    def table_list(self, key: str) -> list[ConfigTable]:
        """An array of inline tables (``key = [{...}, {...}]``); empty when absent."""
        value = self._get(key, [])
        if not isinstance(value, list) or not all(isinstance(v, Mapping) for v in value):
            raise self.error(key, f"must be a list of tables, got {value!r}")
        return [
            ConfigTable(item, table=f"{self._child(key)}[{i}]", source=self.source)
            for i, item in enumerate(value)
        ]

    def done(self) -> None:
        """Refuse every key no getter asked for (a typo names its nearest known key)."""
        unknown = sorted(set(self.values) - self._read)
        if not unknown:
            return
        key = unknown[0]
        close = difflib.get_close_matches(key, sorted(self._read), n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        others = f"; also unknown: {', '.join(map(repr, unknown[1:]))}" if unknown[1:] else ""
        raise ProfileError(
            f"{self.table} has an unknown setting '{key}'{hint}{others} "
            f"(known: {', '.join(sorted(self._read))})",
            source=self.source,
        )

    def _child(self, key: str) -> str:
        return f"[{key}]" if self.table == "(top level)" else f"{self.table[:-1]}.{key}]"


def _as_tuple(kind: type | tuple[type, ...]) -> tuple[type, ...]:
    return kind if isinstance(kind, tuple) else (kind,)
