"""A protocol's details, typed: what a protocol tells the certificate besides its judged
results (its runs and stop rule, the points its plot draws, what a later protocol takes
from it). Each protocol's details are a frozen dataclass derived from :class:`Details`,
written to JSON by :meth:`Details.to_json` and read back by :meth:`Details.from_json`, one
writer and one reader for every protocol: a renamed field breaks the type check and the
reader, not a plot.

JSON keeps the field names; tuples become lists and come back as tuples; a nested
dataclass becomes an object. A field with a default may be absent from what is read (a
certificate written before the field existed); any other absent, mistyped or unknown key
is refused naming the protocol and the key.
"""

from __future__ import annotations

import dataclasses
import functools
import types
import typing
from collections.abc import Mapping
from typing import Any, Self, TypedDict

from hil.errors import HilError


class DetailsError(HilError):
    """A protocol's details that do not read as its declared fields."""


class RunsFields(TypedDict):
    """The fields every protocol's details share (``**repeated.details()``)."""

    runs: int
    stop_rule: str


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class Details:
    """A protocol's details; each protocol declares its fields in a subclass
    (``@dataclass(frozen=True, slots=True, kw_only=True)``)."""

    def to_json(self) -> dict[str, object]:
        """The details as JSON values, field by field."""
        return {f.name: _to_json(getattr(self, f.name)) for f in dataclasses.fields(self)}

    @classmethod
    def from_json(cls, raw: Mapping[str, object], *, where: str) -> Self:
        """The details read back from ``raw`` (as :meth:`to_json` wrote them).

        Raises
        ------
        DetailsError
            A key missing (without a default), unknown, or of another type; naming
            ``where`` (the protocol, the certificate) and the key.
        """
        return typing.cast(Self, _read(cls, raw, where))


def _to_json(value: object) -> object:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _to_json(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, list | tuple):
        return [_to_json(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _to_json(v) for k, v in value.items()}
    return value


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _read(cls: type, raw: object, where: str) -> object:
    if not isinstance(raw, Mapping):
        raise DetailsError(f"{where}: an object expected, got {type(raw).__name__}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(raw) - set(fields))
    if unknown:
        raise DetailsError(f"{where}: unknown key(s) {', '.join(map(str, unknown))}")
    hints = _hints(cls)
    values: dict[str, object] = {}
    for name, field in fields.items():
        if name in raw:
            values[name] = _value(hints[name], raw[name], f"{where}.{name}")
        elif (field.default is dataclasses.MISSING
              and field.default_factory is dataclasses.MISSING):
            raise DetailsError(f"{where}: key {name} missing")
    return cls(**values)


def _value(hint: Any, raw: object, where: str) -> object:
    origin = typing.get_origin(hint)
    arguments = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if raw is None and type(None) in arguments:
            return None
        options = [a for a in arguments if a is not type(None)]
        errors = []
        for option in options:
            try:
                return _value(option, raw, where)
            except DetailsError as exc:
                errors.append(str(exc))
        raise DetailsError(errors[0] if len(errors) == 1 else
                           f"{where}: none of {hint} fits {raw!r:.60}")
    if hint is Any or hint is object:
        return raw
    if dataclasses.is_dataclass(hint):
        return _read(typing.cast(type, hint), raw, where)
    if origin in (list, tuple):
        if not isinstance(raw, list | tuple):
            raise DetailsError(f"{where}: a list expected, got {type(raw).__name__}")
        if origin is tuple and (len(arguments) != 2 or arguments[1] is not Ellipsis):
            if len(arguments) != len(raw):
                raise DetailsError(f"{where}: {len(arguments)} values expected, "
                                   f"got {len(raw)}")
            return tuple(_value(a, v, f"{where}[{i}]")
                         for i, (a, v) in enumerate(zip(arguments, raw, strict=True)))
        item = arguments[0] if arguments else Any
        items = [_value(item, v, f"{where}[{i}]") for i, v in enumerate(raw)]
        return tuple(items) if origin is tuple else items
    if origin is dict or hint is dict:
        if not isinstance(raw, Mapping):
            raise DetailsError(f"{where}: an object expected, got {type(raw).__name__}")
        item = arguments[1] if len(arguments) == 2 else Any
        return {str(k): _value(item, v, f"{where}.{k}") for k, v in raw.items()}
    if hint is float:
        if isinstance(raw, bool) or not isinstance(raw, int | float):
            raise DetailsError(f"{where}: a number expected, got {raw!r:.60}")
        return float(raw)
    if hint is int:
        if isinstance(raw, bool) or not isinstance(raw, int):
            raise DetailsError(f"{where}: an integer expected, got {raw!r:.60}")
        return raw
    if hint in (str, bool):
        if not isinstance(raw, hint):
            raise DetailsError(f"{where}: {hint.__name__} expected, got {raw!r:.60}")
        return raw
    raise DetailsError(f"{where}: cannot read a {hint}")  # a field type this reader lacks


@dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
class RunDetails(Details):
    """The details of a protocol run under a stop rule (:mod:`hil.suite.stop_rule`): how
    many runs it made and why it stopped, then its own fields."""

    runs: int
    stop_rule: str
