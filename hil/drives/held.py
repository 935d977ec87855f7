"""A gimbal's other axes on the bus of the axis under test, held by their own drives: the
part every field-bus backend shares (moving the elevation, what the records state,
releasing them first on leaving)."""

from __future__ import annotations

from typing import Generic, Protocol, TypeVar


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
