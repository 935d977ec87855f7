"""Nelson's (1984) eight tests for special causes on a Shewhart chart (docs/fleet.md §3).

Each rule returns the 0-based indices of the points that complete its pattern: the last
point of every window that satisfies it (a run of 10 on one side fires rule 2 at its 9th
and 10th point). Zones are strict: "beyond 2σ" means ``|x − centre| > 2σ``; a point exactly
on the centre line belongs to neither side; equal neighbours break a trend or an
alternation. Rules 5 and 6 also need the completing point itself to lie beyond the zone,
on the pattern's side; at the start of a series they count the points there are (two
points beyond 2σ at runs 1 and 2 fire rule 5 at run 2).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray

from hil.errors import InputError

DEFAULT_RULES: tuple[int, ...] = (1, 2, 5, 6)

DESCRIPTIONS: dict[int, str] = {
    1: "one point beyond 3σ",
    2: "nine points in a row on one side of the centre line",
    3: "six points in a row steadily increasing or decreasing",
    4: "fourteen points in a row alternating up and down",
    5: "two of three points beyond 2σ on one side",
    6: "four of five points beyond 1σ on one side",
    7: "fifteen points in a row within 1σ",
    8: "eight points in a row beyond 1σ, on both sides",
}

_Array = NDArray[np.float64]


def _ends(mask: NDArray[np.bool_], window: int) -> list[int]:
    """Indices (window ends) where a per-window condition holds."""
    return [int(i) + window - 1 for i in np.flatnonzero(mask)]


def rule_1(z: _Array, x: _Array) -> list[int]:
    """One point beyond 3σ."""
    return [int(i) for i in np.flatnonzero(np.abs(z) > 3.0)]


def rule_2(z: _Array, x: _Array) -> list[int]:
    """Nine in a row on the same side of the centre line."""
    if z.size < 9:
        return []
    w = sliding_window_view(z, 9)
    return _ends(np.all(w > 0, axis=1) | np.all(w < 0, axis=1), 9)


def rule_3(z: _Array, x: _Array) -> list[int]:
    """Six in a row steadily increasing or decreasing (five strict steps one way)."""
    if x.size < 6:
        return []
    d = sliding_window_view(np.diff(x), 5)
    return [i + 1 for i in _ends(np.all(d > 0, axis=1) | np.all(d < 0, axis=1), 5)]


def rule_4(z: _Array, x: _Array) -> list[int]:
    """Fourteen in a row alternating up and down (13 steps, each reversing the last)."""
    if x.size < 14:
        return []
    d = np.diff(x)
    flips = sliding_window_view(d[:-1] * d[1:] < 0, 12)
    return [i + 2 for i in _ends(np.all(flips, axis=1), 12)]


def _k_of_m(z: _Array, k: int, m: int, bound: float) -> list[int]:
    """Indices i where i is beyond ``bound`` and at least k of the last m points (fewer at
    the start of the series) are beyond it on the same side."""
    if z.size == 0:
        return []
    padded = np.concatenate([np.zeros(m - 1), z])  # before the first point: not beyond
    hits: list[int] = []
    for sign in (1.0, -1.0):
        beyond = sign * padded > bound
        counts = sliding_window_view(beyond, m).sum(axis=1)
        hits += [int(i) for i in np.flatnonzero((counts >= k) & beyond[m - 1:])]
    return sorted(set(hits))


def rule_5(z: _Array, x: _Array) -> list[int]:
    """Two of three in a row beyond 2σ on the same side."""
    return _k_of_m(z, 2, 3, 2.0)


def rule_6(z: _Array, x: _Array) -> list[int]:
    """Four of five in a row beyond 1σ on the same side."""
    return _k_of_m(z, 4, 5, 1.0)


def rule_7(z: _Array, x: _Array) -> list[int]:
    """Fifteen in a row within 1σ of the centre line (either side)."""
    if z.size < 15:
        return []
    return _ends(np.all(np.abs(sliding_window_view(z, 15)) < 1.0, axis=1), 15)


def rule_8(z: _Array, x: _Array) -> list[int]:
    """Eight in a row beyond 1σ, with points on both sides."""
    if z.size < 8:
        return []
    w = sliding_window_view(z, 8)
    mask = np.all(np.abs(w) > 1.0, axis=1) & np.any(w > 1.0, axis=1) & np.any(w < -1.0, axis=1)
    return _ends(mask, 8)


_RULES: dict[int, Callable[[_Array, _Array], list[int]]] = {
    1: rule_1, 2: rule_2, 3: rule_3, 4: rule_4, 5: rule_5, 6: rule_6, 7: rule_7, 8: rule_8,
}


def parse_rules(rules: Iterable[int] | str) -> tuple[int, ...]:
    """``"1,2,5,6"``, ``"all"`` or integers → a sorted tuple of rule numbers 1–8."""
    if isinstance(rules, str):
        text = rules.strip().lower()
        if text == "all":
            return tuple(range(1, 9))
        try:
            numbers = [int(part) for part in text.split(",") if part.strip()]
        except ValueError as exc:
            raise InputError(f"rules: '{rules}' is not a comma-separated list of 1–8") from exc
    else:
        numbers = [int(r) for r in rules]
    bad = [r for r in numbers if r not in _RULES]
    if bad:
        raise InputError(f"rules: {bad} are not Nelson rules (1–8)")
    if not numbers:
        raise InputError("rules: no rule selected")
    return tuple(sorted(set(numbers)))


def nelson_rules(values: ArrayLike, *, centre: float, sigma: float,
                 rules: Iterable[int] | str = DEFAULT_RULES) -> dict[int, list[int]]:
    """Apply the selected Nelson rules to an individuals chart.

    Parameters
    ----------
    values : array_like
        The plotted points in time order.
    centre : float
        Centre line.
    sigma : float
        σ of one plotted point (MR̄/d2 on an individuals chart).
    rules : iterable of int or str
        Rule numbers 1–8, ``"1,2,5,6"`` or ``"all"``; default 1, 2, 5, 6.

    Returns
    -------
    dict
        Rule number → sorted 0-based indices where it fires (an empty list when it
        does not).
    """
    selected = parse_rules(rules)
    if not sigma > 0.0 or not np.isfinite(sigma):
        raise InputError(f"Nelson rules need a positive σ, got {sigma}")
    x = np.asarray(values, dtype=float)
    z = (x - centre) / sigma
    return {r: _RULES[r](z, x) for r in selected}
