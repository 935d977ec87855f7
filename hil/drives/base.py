"""The Drive contract: execute a sampled command trajectory, return a Recording.

Above ``hil/drives`` everything is SI floats with the unit in the name; unit conversion to
counts, per-mille of rated torque or vendor units lives only inside a backend.
"""

from __future__ import annotations

import abc
import logging
from dataclasses import dataclass
from enum import Enum
from types import TracebackType

import numpy as np
from numpy.typing import NDArray

from hil.errors import LimitViolationError
from hil.motion import Excitation, Limits, Mode
from hil.recording import Recording

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]


class DriveState(Enum):
    DISABLED = "disabled"
    ENABLED = "enabled"
    QUICK_STOPPED = "quick_stopped"
    FAULT = "fault"


@dataclass(frozen=True, slots=True, kw_only=True)
class DriveInfo:
    """What the certificate records about the drive, and what protocols may rely on."""

    vendor: str
    model: str
    firmware_version: str
    serial: str
    rated_torque_nm: float
    limits: Limits
    modes: tuple[Mode, ...]
    max_sample_rate_hz: float
    has_torque_sensor: bool = False
    transport: str = "none"


@dataclass(frozen=True, slots=True, kw_only=True)
class DriveStatus:
    state: DriveState
    position_rad: float
    velocity_rad_s: float
    fault_code: int | None = None


def check_limits(excitation: Excitation, limits: Limits, *, start_position_rad: float) -> None:
    """Refuse an excitation that would leave the envelope (before any motion).

    Velocity commands are integrated from ``start_position_rad`` to check travel; position
    commands are checked directly and their finite-difference velocity too.
    """
    command = np.asarray(excitation.command, dtype=np.float64)
    where = f"excitation '{excitation.name}'"
    if command.ndim != 1 or command.size == 0:
        raise LimitViolationError(f"{where}: command must be a non-empty 1-D array")
    if not np.all(np.isfinite(command)):
        raise LimitViolationError(f"{where}: command holds non-finite samples")
    if excitation.mode is Mode.TORQUE:
        _check_peak(where, "torque", command, limits.torque_nm, "N·m")
        return
    if excitation.mode is Mode.VELOCITY:
        _check_peak(where, "velocity", command, limits.velocity_rad_s, "rad/s")
        travel = start_position_rad + np.cumsum(command) / excitation.fs_hz
    else:
        travel = command
        velocity = np.diff(command, prepend=start_position_rad) * excitation.fs_hz
        _check_peak(where, "velocity", velocity, limits.velocity_rad_s, "rad/s")
    low, high = float(travel.min()), float(travel.max())
    if low < limits.travel_min_rad or high > limits.travel_max_rad:
        raise LimitViolationError(
            f"{where}: travel [{low:.4g}, {high:.4g}] rad leaves the limits "
            f"[{limits.travel_min_rad:.4g}, {limits.travel_max_rad:.4g}] rad"
        )


def _check_peak(where: str, what: str, values: FloatArray, limit: float, unit: str) -> None:
    peak = float(np.max(np.abs(values)))
    if peak > limit:
        raise LimitViolationError(
            f"{where}: peak {what} {peak:.4g} {unit} exceeds {limit:.4g} {unit}"
        )


class Drive(abc.ABC):
    """A drive backend. ``disable`` is idempotent and always safe to call.

    Use as a context manager: leaving the block disables the drive whatever happened.
    """

    @property
    @abc.abstractmethod
    def info(self) -> DriveInfo: ...

    @abc.abstractmethod
    def enable(self) -> None: ...

    @abc.abstractmethod
    def disable(self) -> None: ...

    @abc.abstractmethod
    def quick_stop(self) -> None: ...

    @abc.abstractmethod
    def status(self) -> DriveStatus: ...

    @abc.abstractmethod
    def run(self, excitation: Excitation) -> Recording:
        """Execute ``excitation`` and return what was measured.

        Raises
        ------
        LimitViolationError
            The command leaves the unit's limits; nothing moved.
        DriveError
            A fault or communication loss; the drive is already safe. The partial
            recording, if any, is attached as ``exc.partial_recording``.
        """

    def close(self) -> None:
        """Release the transport. Disables first."""
        self.disable()

    def __enter__(self) -> Drive:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc is not None:
            try:
                self.quick_stop()
            except Exception:  # the original error matters more; disable still runs
                log.exception("quick stop failed while handling %r", exc)
        self.close()
