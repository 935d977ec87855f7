"""What the fleet statistics read: a stored result per run (:class:`SeriesPoint`) and a stored
run (:class:`RunRecord`). Any object with these attributes will do (the results store's
``StoredResult`` has exactly the first set); nothing here imports the store."""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from hil.errors import InputError


class SeriesPoint(Protocol):
    """One judged result of one calibration run."""

    @property
    def run_id(self) -> str: ...
    @property
    def certificate_id(self) -> str: ...
    @property
    def serial(self) -> str: ...
    @property
    def station(self) -> str: ...
    @property
    def started_at(self) -> datetime: ...
    @property
    def value(self) -> float: ...
    @property
    def standard_uncertainty(self) -> float: ...
    @property
    def expanded_uncertainty(self) -> float: ...
    @property
    def unit(self) -> str: ...
    @property
    def nominal(self) -> float | None: ...
    @property
    def lower_limit(self) -> float | None: ...
    @property
    def upper_limit(self) -> float | None: ...
    @property
    def outcome(self) -> str: ...
    @property
    def is_reference(self) -> bool: ...


class RunRecord(Protocol):
    """One calibration run (for first-pass yield)."""

    @property
    def serial(self) -> str: ...
    @property
    def station(self) -> str: ...
    @property
    def started_at(self) -> datetime: ...
    @property
    def outcome(self) -> str: ...
    @property
    def attempt(self) -> int: ...
    @property
    def aborted(self) -> bool: ...
    @property
    def is_reference(self) -> bool: ...
    @property
    def axis(self) -> str: ...  # a gimbal's axes share its serial; each has first passes


SERIES_FIELDS: tuple[str, ...] = (
    "run_id", "certificate_id", "serial", "station", "started_at", "value",
    "standard_uncertainty", "expanded_uncertainty", "unit", "nominal", "lower_limit",
    "upper_limit", "outcome", "is_reference",
)
"""The attributes of a :class:`SeriesPoint`, in export column order."""


def ordered(points: Sequence[SeriesPoint], *,
            include_reference: bool = False) -> list[SeriesPoint]:
    """Points in time order (ties by run id); reference (golden) units left out unless asked.

    Raises
    ------
    InputError
        A point has a value that is not finite.
    """
    kept = [p for p in points if include_reference or not p.is_reference]
    for p in kept:
        if not np.isfinite(p.value):
            raise InputError(f"run {p.run_id} (serial {p.serial}): value {p.value} "
                             "is not finite")
    aware = {p.started_at.tzinfo is not None for p in kept}
    if len(aware) > 1:
        raise InputError("the runs mix timestamps with and without a time zone")
    return sorted(kept, key=lambda p: (p.started_at, p.run_id))


def values_of(points: Sequence[SeriesPoint]) -> NDArray[np.float64]:
    """The values as a float array, in the given order."""
    return np.array([float(p.value) for p in points], dtype=float)


def single_unit(points: Sequence[SeriesPoint]) -> str:
    """The one unit the points share.

    Raises
    ------
    InputError
        The series mixes units (two parameters, or a renamed unit).
    """
    units = sorted({p.unit for p in points})
    if len(units) > 1:
        raise InputError(f"the series mixes units {units}: one parameter at a time")
    return units[0] if units else ""


def spec_limits(points: Sequence[SeriesPoint]) -> tuple[float | None, float | None]:
    """The specification limits of the most recent point (profiles can change them)."""
    if not points:
        return None, None
    last = points[-1]
    return last.lower_limit, last.upper_limit
