"""A gimbal's other axes on the bus of the axis under test, held by their own drives: the
part every field-bus backend shares (moving the elevation, what the records state,
releasing them first on leaving)."""

from __future__ import annotations

import math
from typing import Generic, Protocol, TypeVar

import numpy as np


class Held(Protocol):
    """One held axis (a CiA 402 node, a Modbus unit)."""

    @property
    def address(self) -> str:
        """``node 6``, ``unit 2``: where it is on the bus."""

    @property
    def position_rad(self) -> float:
        """Where it stands (read from its drive)."""

    def move_to(self, angle_rad: float) -> None: ...

    def disable(self) -> None: ...


H = TypeVar("H", bound=Held)


class HeldAxes(Generic[H]):
    """The held axes by name, in the order the station names them (``H``: the backend's
    held-axis class)."""

    def __init__(self) -> None:
        self.axes: dict[str, H] = {}

    def move(self, name: str, angle_rad: float) -> bool:
        """Move the held axis ``name`` to ``angle_rad``; ``False`` when there is none."""
        axis = self.axes.get(name)
        if axis is None:
            return False
        axis.move_to(angle_rad)
        return True

    def text(self) -> str:
        """``elevation node 6 at +0.6000 rad``, one per held axis: the certificate states
        where the gimbal's other axes stood."""
        return "; ".join(f"{name} {axis.address} at {axis.position_rad:+.4f} rad"
                         for name, axis in self.axes.items())

    def release(self) -> None:
        """Disable each (each logs what it cannot confirm)."""
        for axis in self.axes.values():
            axis.disable()


def trapezoid_rad(start_rad: float, end_rad: float, *, speed_rad_s: float,
                  accel_rad_s2: float, step_s: float) -> np.ndarray:
    """Positions every ``step_s`` of a move from ``start_rad`` to ``end_rad`` at most at
    ``speed_rad_s``, accelerating and braking at ``accel_rad_s2`` (the last one the end)."""
    distance = abs(end_rad - start_rad)
    top = min(speed_rad_s, math.sqrt(distance * accel_rad_s2))
    ramp_s = top / accel_rad_s2
    cruise_s = distance / top - ramp_s if top > 0 else 0.0
    total_s = 2 * ramp_s + cruise_s
    t = np.append(np.arange(1, max(1, math.ceil(total_s / step_s))) * step_s, total_s)
    up = 0.5 * accel_rad_s2 * np.minimum(t, ramp_s) ** 2
    flat = top * np.clip(t - ramp_s, 0.0, cruise_s)
    down = np.clip(t - ramp_s - cruise_s, 0.0, ramp_s)
    travelled = up + flat + top * down - 0.5 * accel_rad_s2 * down**2
    sign = math.copysign(1.0, end_rad - start_rad)
    return np.asarray(start_rad + sign * np.minimum(travelled, distance), dtype=np.float64)
