"""What a protocol asks of the gimbal's other axis, and what it does to it: whether two
protocols on different axes of one gimbal may run at the same time.

The baseline every protocol is calibrated under is the other axis *held still by its
drive*. A protocol may run beside another when neither's motion reaches the other's
measurement beyond that baseline:

- ``still``: it measures with its rotor clamped, so the other axis sees the baseline it is
  calibrated under (a shared gimbal runs its clamped runs beside the other axis's clamped
  runs only: a move between them waits, since a clamp's sensor feels the other's motion);
- ``indifferent``: its result does not depend on the other axis's motion (an electrical
  measurement, not a mechanical one);
- ``moves_other``: it moves the other axis itself (the azimuth's inertia across elevation,
  the cross-coupling), so nothing runs beside it.

A mechanical identification is neither still nor indifferent: the elevation's motion
changes the azimuth's inertia (``J_az(el)``) and puts its reaction torques on it, and the
azimuth's motion puts centrifugal and reaction torques on the elevation.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache


@dataclass(frozen=True, slots=True, kw_only=True)
class Beside:
    """How a protocol shares the gimbal with the other axis's protocol (module docstring)."""

    still: bool = False
    indifferent: bool = False
    moves_other: bool = False

    def __post_init__(self) -> None:
        if self.moves_other and (self.still or self.indifferent):
            raise ValueError("a protocol that moves the other axis shares the gimbal with "
                             "nothing: it is neither still nor indifferent to it")


#: a mechanical identification: needs the other axis held, and disturbs it
ALONE = Beside()


def together(first: Beside, second: Beside) -> bool:
    """Whether two protocols on different axes may run at the same time: each one's
    measurement is indifferent to the other's motion, or the other does not move."""
    if first.moves_other or second.moves_other:
        return False
    return (first.indifferent or second.still) and (second.indifferent or first.still)


@dataclass(frozen=True, slots=True, kw_only=True)
class Planned:
    """One protocol of an axis, as the plan sees it: its planned motion and how it shares."""

    name: str
    motion_s: float
    beside: Beside = ALONE


@dataclass(frozen=True, slots=True)
class Step:
    """Protocols that run at the same time: one index into each axis's list, or ``None``
    where that axis runs nothing in this step."""

    first: int | None
    second: int | None


def plan_together(first: Sequence[Planned], second: Sequence[Planned],
                  allowed: Callable[[Planned, Planned], bool] | None = None
                  ) -> tuple[Step, ...]:
    """The shortest schedule of two axes' protocols, each axis's in its own order, two of
    them at a time only where ``allowed`` (default: :func:`together` of their
    declarations) says so (a step lasts its longer protocol).

    Returns
    -------
    tuple of Step
        In order; each protocol of each axis appears in exactly one step.
    """
    if allowed is None:
        def allowed(a: Planned, b: Planned) -> bool:
            return together(a.beside, b.beside)

    @cache
    def best(i: int, j: int) -> tuple[float, tuple[Step, ...]]:
        if i == len(first) and j == len(second):
            return 0.0, ()
        options = []
        if i < len(first):
            rest, steps = best(i + 1, j)
            options.append((first[i].motion_s + rest, (Step(i, None), *steps)))
        if j < len(second):
            rest, steps = best(i, j + 1)
            options.append((second[j].motion_s + rest, (Step(None, j), *steps)))
        if i < len(first) and j < len(second) and allowed(first[i], second[j]):
            rest, steps = best(i + 1, j + 1)
            options.append((max(first[i].motion_s, second[j].motion_s) + rest,
                            (Step(i, j), *steps)))
        return min(options, key=lambda option: option[0])

    return best(0, 0)[1]
