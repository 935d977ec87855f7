"""The Drive contract: execute a sampled command trajectory, return a Recording.

Above ``hil/drives`` everything is SI floats with the unit in the name; unit conversion to
counts, per-mille of rated torque or vendor units lives only inside a backend.
"""

from __future__ import annotations

import abc
import dataclasses
import logging
from collections.abc import Iterable, Mapping
from contextlib import AbstractContextManager
from dataclasses import dataclass
from enum import Enum
from types import TracebackType

import numpy as np
from numpy.typing import NDArray

from hil.errors import DriveStateError, LimitViolationError
from hil.motion import CompensationTable, Excitation, Limits, Mode
from hil.recording import Recording

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]


class DriveState(Enum):
    """The drive's power state as the contract sees it (CiA 402's states map onto these)."""

    DISABLED = "disabled"
    ENABLED = "enabled"
    QUICK_STOPPED = "quick_stopped"
    FAULT = "fault"


class Capability(Enum):
    """What a station can do beyond the drive contract, declared once per drive in
    :attr:`DriveInfo.capabilities`. A protocol names the ones it needs (its suite module's
    ``REQUIRES``) and is skipped, with them named, on a station that lacks one; the drive
    method that uses one raises :class:`DriveStateError` where it is not declared."""

    TORQUE_SENSOR = "shaft torque sensor"
    LOCKED_ROTOR = "locked-rotor fixture (Drive.locked_rotor)"
    ELEVATION_AXIS = "elevation axis the harness can move (Drive.set_elevation)"
    ELEVATION_MOTION = ("elevation axis that follows a path while this axis runs "
                        "(Excitation.elevation_path_rad)")
    COMPENSATION_TABLE = "cogging compensation table (Drive.load_compensation)"


@dataclass(frozen=True, slots=True, kw_only=True)
class Recorder:
    """A drive's own recorder: it samples faster than the link streams, but holds a bounded
    run and may play no torque offset. A run above ``stream_rate_hz`` goes to it.

    Attributes
    ----------
    stream_rate_hz : float
        The fastest rate the link streams, for a run of any length.
    samples : int
        The most samples one run may have in the recorder.
    torque_offset : bool
        It plays a torque offset (feedforward) sample by sample with the command.
    """

    stream_rate_hz: float
    samples: int
    torque_offset: bool = False

    def refuses(self, excitation: Excitation) -> str | None:
        """``None`` when ``excitation`` streams or fits the recorder; else why it does not."""
        if excitation.fs_hz <= self.stream_rate_hz * (1 + 1e-9):
            return None
        if excitation.torque_offset_nm is not None and not self.torque_offset:
            return f"'{excitation.name}' sends a torque offset; the drive recorder plays none"
        if len(excitation.command) > self.samples:
            return (f"'{excitation.name}' has {len(excitation.command):,} samples at "
                    f"{excitation.fs_hz:g} Hz; the drive recorder holds {self.samples:,}")
        return None


@dataclass(frozen=True, slots=True, kw_only=True)
class DriveInfo:
    """What the certificate records about the drive, and what protocols may rely on.

    Attributes
    ----------
    vendor, model, firmware_version, serial : str
        As the drive reports them (its identity object or registers).
    rated_torque_nm : float
        The torque the drive's per-mille or percent units refer to.
    limits : Limits
        The envelope this drive enforces before any motion.
    modes : tuple of Mode
        The control modes :meth:`Drive.run` accepts.
    max_sample_rate_hz : float
        The fastest rate a recording can be sampled at over this transport.
    capabilities : frozenset of Capability
        What the station can do beyond the contract (a torque sensor, a fixture, ...).
    recorder : Recorder or None
        When ``max_sample_rate_hz`` is reached only by the drive's own recorder (bounded
        runs): its limits and the rate the link streams.
    torque_sensor : str
        The shaft torque sensor and its calibration certificate ("" : none, or the
        simulator's own, exact).
    torque_sensor_relative_u : float
        The relative standard uncertainty of its sensitivity (its certificate's U over k):
        a Type B line of every result scaled by it (K_t).
    timing : mapping of str to str
        What this drive's recordings state about their timing and the drive's conventions
        (torque sampling, control period, the object map's ``position_latch`` and
        ``torque_reports``): a protocol checks before motion that its model applies.
    transport : str
        ``"sim"``, ``"canopen ..."``, ``"modbus tcp"``, ...: for messages and skips.
    """

    vendor: str
    model: str
    firmware_version: str
    serial: str
    rated_torque_nm: float
    limits: Limits
    modes: tuple[Mode, ...]
    max_sample_rate_hz: float
    capabilities: frozenset[Capability] = frozenset()
    recorder: Recorder | None = None
    torque_sensor: str = ""
    torque_sensor_relative_u: float = 0.0
    timing: Mapping[str, str] = dataclasses.field(default_factory=dict)
    transport: str = "none"

    def identity(self) -> dict[str, str]:
        """The drive as every recording's metadata names it (model, firmware, serial,
        transport); each drive kind adds its address."""
        return {"model": self.model, "firmware": self.firmware_version, "serial": self.serial,
                "transport": self.transport}

    def streamed(self) -> DriveInfo:
        """This drive as one that streams every run (no recorder, its stream rate)."""
        if self.recorder is None:
            return self
        return dataclasses.replace(self, max_sample_rate_hz=self.recorder.stream_rate_hz,
                                   recorder=None)

    def lacking(self, required: Iterable[Capability]) -> str | None:
        """``None`` when the station has every one of ``required``, else one line naming
        what it lacks (a protocol's skip reason)."""
        missing = [c.value for c in required if c not in self.capabilities]
        if not missing:
            return None
        return f"the station ({self.transport}) lacks: {'; '.join(missing)}"


@dataclass(frozen=True, slots=True, kw_only=True)
class DriveStatus:
    """A snapshot of the drive.

    Attributes
    ----------
    state : DriveState
        The power state, as the contract sees it.
    position_rad, velocity_rad_s : float
        The axis' encoder position and the drive's velocity estimate.
    fault_code : int or None
        The drive's fault code while in :attr:`DriveState.FAULT`.
    """

    state: DriveState
    position_rad: float
    velocity_rad_s: float
    fault_code: int | None = None


class Interrupted(KeyboardInterrupt):
    """A stop signal (SIGINT; SIGTERM and SIGHUP raise ``KeyboardInterrupt`` too) during
    :meth:`Drive.run`: the backend quick-stopped the drive and attaches the rows acquired
    so far as ``partial_recording`` (``None`` when none were), then re-raises this."""

    def __init__(self, message: str, *, partial_recording: Recording | None) -> None:
        super().__init__(message)
        self.partial_recording = partial_recording


def interrupted(stop: KeyboardInterrupt, recording: Recording | None) -> Interrupted:
    """``stop`` with the rows acquired so far attached (raise it ``from stop``); an
    :class:`Interrupted` already carrying rows is kept as it is."""
    if isinstance(stop, Interrupted) and stop.partial_recording is not None:
        return stop
    rows = recording if recording is not None and len(recording) > 0 else None
    return Interrupted(str(stop) or "interrupted", partial_recording=rows)


MONITOR_TRAVEL_MARGIN_RAD = 0.05  # beyond the travel limits before the monitor trips
MONITOR_VELOCITY_MARGIN = 0.25  # relative, beyond the velocity limit (loop overshoot, noise)


@dataclass(frozen=True, slots=True, kw_only=True)
class MotionEnvelope:
    """What the motion monitor allows while the axis moves: the unit's travel and velocity
    limits widened by a stated margin (:data:`MONITOR_TRAVEL_MARGIN_RAD`,
    :data:`MONITOR_VELOCITY_MARGIN`), so a command inside the limits never trips it while
    one that runs away (a torque command, a loop gone wrong) is stopped."""

    limits: Limits
    position_min_rad: float
    position_max_rad: float
    velocity_rad_s: float

    @classmethod
    def of(cls, limits: Limits) -> MotionEnvelope:
        """The envelope the monitor enforces for ``limits``."""
        return cls(
            limits=limits,
            position_min_rad=limits.travel_min_rad - MONITOR_TRAVEL_MARGIN_RAD,
            position_max_rad=limits.travel_max_rad + MONITOR_TRAVEL_MARGIN_RAD,
            velocity_rad_s=limits.velocity_rad_s * (1 + MONITOR_VELOCITY_MARGIN),
        )

    def violation(
        self, *, position_rad: float, velocity_rad_s: float, time_s: float, excitation: str
    ) -> LimitViolationError | None:
        """The error for a measured sample outside the envelope (``None`` inside): one line
        naming the limit, the value and the time into the excitation."""
        lim = self.limits
        if not self.position_min_rad <= position_rad <= self.position_max_rad:
            what = (f"position {position_rad:.4g} rad left the travel limits "
                    f"[{lim.travel_min_rad:.4g}, {lim.travel_max_rad:.4g}] rad "
                    f"(+{MONITOR_TRAVEL_MARGIN_RAD:g} rad margin)")
        elif not abs(velocity_rad_s) <= self.velocity_rad_s:
            what = (f"velocity {velocity_rad_s:.4g} rad/s exceeds the limit "
                    f"{lim.velocity_rad_s:.4g} rad/s (+{MONITOR_VELOCITY_MARGIN:.0%} margin)")
        else:
            return None
        return LimitViolationError(
            f"excitation '{excitation}': measured {what} at t = {time_s:.3f} s; "
            "the axis was quick-stopped"
        )


def check_limits(excitation: Excitation, limits: Limits, *, start_position_rad: float) -> None:
    """Refuse an excitation that would leave the envelope (before any motion).

    Velocity commands are integrated from ``start_position_rad`` to check travel; position
    commands are checked directly and their finite-difference velocity too.

    Parameters
    ----------
    excitation : Excitation
        The command trajectory about to be run.
    limits : Limits
        The unit's envelope.
    start_position_rad : float
        Where the axis is now.

    Raises
    ------
    LimitViolationError
        The command is empty or non-finite, or its peak torque, peak velocity or travel
        leaves ``limits``; the message names the excitation, the quantity and both values.
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
    """A drive backend: executes sampled command trajectories and records what happened.

    Everything crossing this interface is in SI units; unit conversion lives in the
    backend. :meth:`disable` is idempotent and always safe to call.

    Notes
    -----
    Use as a context manager: leaving the block quick-stops the drive if an exception is
    propagating, then closes it (which disables it) whatever happened.

    Examples
    --------
    >>> with open_drive("sim", profile=profile, unit_serial="X") as drive:  # doctest: +SKIP
    ...     drive.enable()
    ...     recording = drive.run(excitation)
    """

    @property
    @abc.abstractmethod
    def info(self) -> DriveInfo:
        """What the drive is and can do.

        Returns
        -------
        DriveInfo
            Identity, rated torque, limits, modes and the fastest sample rate, read (or
            measured) once when the drive connected.
        """

    @abc.abstractmethod
    def enable(self) -> None:
        """Bring the drive to an enabled state, holding its position.

        Raises
        ------
        DriveError
            The drive did not reach the state in time, or is in fault.
        """

    @abc.abstractmethod
    def disable(self) -> None:
        """Remove torque.

        Idempotent and always safe to call, also after a fault or a lost link: then it does
        what it still can and logs the rest; it does not raise a :class:`DriveError`.
        """

    @abc.abstractmethod
    def quick_stop(self) -> None:
        """Decelerate to standstill by the drive's quick-stop ramp.

        The drive then holds or disables as its quick-stop option says. Safe to call after
        a fault or a lost link: what cannot be confirmed is logged, not raised.
        """

    @abc.abstractmethod
    def status(self) -> DriveStatus:
        """The drive's state, position and velocity now.

        Returns
        -------
        DriveStatus
            Read from the drive (not remembered), with its fault code while in fault.

        Raises
        ------
        DriveError
            The drive cannot be read.
        """

    @abc.abstractmethod
    def run(self, excitation: Excitation) -> Recording:
        """Execute ``excitation`` and return what was measured.

        Parameters
        ----------
        excitation : Excitation
            One command sample per control period at ``excitation.fs_hz``, in the mode
            ``excitation.mode`` (N·m, rad/s or rad).

        Returns
        -------
        Recording
            One row per command sample: time, command, encoder position, velocity, reported
            torque (and current, load torque where the drive has them), with metadata
            stating how the samples were timed.

        Raises
        ------
        LimitViolationError
            The command leaves the unit's limits (nothing moved), or the measured position
            or velocity left the :class:`MotionEnvelope` while moving (the axis
            quick-stopped, the recording up to then on ``exc.partial_recording``).
        DriveError
            A fault or communication loss; the drive is already safe. The partial
            recording, if any, is attached as ``exc.partial_recording``.
        """

    def load_compensation(self, table: CompensationTable | None) -> None:
        """Load a cogging compensation table into the drive (``None``: clear it).

        The drive applies it only when its firmware has cogging compensation.

        Raises
        ------
        DriveStateError
            The station has no :attr:`Capability.COMPENSATION_TABLE`.
        """
        raise self._without(Capability.COMPENSATION_TABLE)

    def locked_rotor(self) -> AbstractContextManager[None]:
        """The rotor clamped (the shaft torque sensor reading the torque) inside the block,
        released after it.

        Raises
        ------
        DriveStateError
            The station has no :attr:`Capability.LOCKED_ROTOR`.
        """
        raise self._without(Capability.LOCKED_ROTOR)

    def set_elevation(self, elevation_rad: float) -> None:
        """Put the station's elevation axis at ``elevation_rad`` (the azimuth inertia across
        elevation).

        Raises
        ------
        DriveStateError
            The station has no :attr:`Capability.ELEVATION_AXIS`.
        """
        raise self._without(Capability.ELEVATION_AXIS)

    def begin_protocol(self, name: str) -> None:  # noqa: B027 (a hook: most drives need none)
        """Protocol ``name`` is about to start (a drive shared with another axis's
        calibration may wait here until it can run beside the other's)."""

    def end_protocol(self) -> None:  # noqa: B027 (a hook: most drives need none)
        """The protocol begun last has ended."""

    def _without(self, capability: Capability) -> DriveStateError:
        return DriveStateError(f"the station ({self.info.transport}) lacks: "
                               f"{capability.value}")

    def close(self) -> None:
        """Disable the drive, then release the transport."""
        self.disable()

    def __enter__(self) -> Drive:
        """Return the drive itself."""
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        """Quick-stop if an exception propagates (its own failure logged), then close."""
        if exc is not None:
            try:
                self.quick_stop()
            except Exception:  # the original error matters more; disable still runs
                log.exception("quick stop failed while handling %r", exc)
        self.close()
