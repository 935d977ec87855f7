"""A frozen I-MR baseline: the centre line and MR̄ of at least 25 in-control runs, kept so
later runs are judged against fixed limits (docs/fleet.md §2)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime

from hil.errors import InputError
from hil.fleet.capability import D2, moving_ranges
from hil.fleet.series import SeriesPoint, ordered, single_unit, values_of

MIN_BASELINE_POINTS = 25
"""Fewest runs a baseline may be frozen from (Montgomery: 20–25 preliminary samples)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Baseline:
    """Frozen I-MR chart parameters of one measured parameter."""

    parameter: str
    unit: str
    n: int
    centre: float
    mr_bar: float
    first_started_at: str
    last_started_at: str
    frozen_at: str
    run_ids: tuple[str, ...]

    @property
    def sigma(self) -> float:
        """σ = MR̄/d2 of the baseline runs."""
        return self.mr_bar / D2

    def to_dict(self) -> dict[str, object]:
        """JSON-ready dict; :meth:`from_dict` reads it back."""
        return {"parameter": self.parameter, "unit": self.unit, "n": self.n,
                "centre": self.centre, "mr_bar": self.mr_bar, "sigma": self.sigma,
                "first_started_at": self.first_started_at,
                "last_started_at": self.last_started_at, "frozen_at": self.frozen_at,
                "run_ids": list(self.run_ids)}

    @classmethod
    def from_dict(cls, data: Mapping[str, object], *, source: str = "baseline") -> Baseline:
        """Read a dict written by :meth:`to_dict` (``sigma`` is recomputed, not read).

        Raises
        ------
        InputError
            A key is missing or has the wrong type, naming ``source`` and the key.
        """
        def get(key: str) -> object:
            if key not in data:
                raise InputError(f"missing key '{key}'", source=source)
            return data[key]

        def wrong(key: str, want: str) -> InputError:
            return InputError(f"key '{key}' must be {want}, not "
                              f"{type(data[key]).__name__}", source=source)

        def text(key: str) -> str:
            value = get(key)
            if not isinstance(value, str):
                raise wrong(key, "a string")
            return value

        def number(key: str) -> float:
            value = get(key)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise wrong(key, "a number")
            if not math.isfinite(value):
                raise InputError(f"key '{key}' is not finite", source=source)
            return float(value)

        n_value, run_ids = get("n"), get("run_ids")
        if isinstance(n_value, bool) or not isinstance(n_value, int):
            raise wrong("n", "an integer")
        if not isinstance(run_ids, list) or not all(isinstance(r, str) for r in run_ids):
            raise InputError("key 'run_ids' must be a list of strings", source=source)
        if n_value < MIN_BASELINE_POINTS:
            raise InputError(f"key 'n' is {n_value}: a baseline holds at least "
                             f"{MIN_BASELINE_POINTS} runs", source=source)
        mr_bar = number("mr_bar")
        if mr_bar <= 0.0:
            raise InputError("key 'mr_bar' must be positive", source=source)
        return cls(parameter=text("parameter"), unit=text("unit"), n=n_value,
                   centre=number("centre"), mr_bar=mr_bar,
                   first_started_at=text("first_started_at"),
                   last_started_at=text("last_started_at"), frozen_at=text("frozen_at"),
                   run_ids=tuple(run_ids))


def freeze_baseline(points: Sequence[SeriesPoint], *, parameter: str,
                    frozen_at: datetime, include_reference: bool = False) -> Baseline:
    """Freeze the I-MR centre and MR̄ of ``points`` (reference units left out by default).

    Raises
    ------
    InputError
        Fewer than 25 runs, or runs that do not vary.
    """
    runs = ordered(points, include_reference=include_reference)
    if len(runs) < MIN_BASELINE_POINTS:
        raise InputError(f"a baseline for '{parameter}' needs at least {MIN_BASELINE_POINTS} "
                         f"runs, got {len(runs)}")
    x = values_of(runs)
    mr_bar = float(moving_ranges(x).mean())
    if not mr_bar > 0.0:
        raise InputError(f"a baseline for '{parameter}': the {len(runs)} values do not vary")
    return Baseline(parameter=parameter, unit=single_unit(runs), n=len(runs),
                    centre=float(x.mean()), mr_bar=mr_bar,
                    first_started_at=runs[0].started_at.isoformat(),
                    last_started_at=runs[-1].started_at.isoformat(),
                    frozen_at=frozen_at.isoformat(), run_ids=tuple(p.run_id for p in runs))
