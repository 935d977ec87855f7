"""SimDrive: the Drive contract over :mod:`plant_sim` (runs far faster than real time)."""

from __future__ import annotations

import contextlib
import logging
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np

from hil.drives.base import (
    Capability,
    Drive,
    DriveInfo,
    DriveState,
    DriveStatus,
    MotionEnvelope,
    check_limits,
    interrupted,
)
from hil.drives.gimbal_link import GimbalLink
from hil.drives.held import trapezoid_rad
from hil.errors import DriveStateError
from hil.motion import CompensationTable, Excitation, Limits, Mode, PositionHarmonic
from hil.recording import Recording
from plant_sim.firmware import Firmware
from plant_sim.gimbal import AxisBlock, GimbalPlant
from plant_sim.model import (
    MotionGuard,
    Plant,
    PlantTrace,
    concatenate_traces,
    trace_to_recording,
)
from plant_sim.params import Harmonic, PlantParams

log = logging.getLogger(__name__)

QUICK_STOP_DECEL_RAD_S2 = 20.0  # the simulated drive's quick-stop ramp (as the emulators')
QUICK_STOP_HOLD_S = 0.05  # held at zero velocity after the ramp
HOLD_SPEED_RAD_S = 1.0  # how the simulated station moves a held axis (as the emulators')
HOLD_ACCEL_RAD_S2 = 4.0
HOLD_SETTLE_S = 0.2  # standing after a move, before the next run
PARTNER_SEED = 0x6A  # the held axis's plant seeds its noise with seed + (this << 32)
PACE_PIECE_S = 0.05  # of motion per kernel call when paced: a stop lands within one


@dataclass(frozen=True, slots=True, kw_only=True)
class GimbalPartner:
    """The gimbal's other axis, simulated with the axis under test (one two-axis plant) and
    held by its own drive in position control: ``outer`` when it carries the axis under
    test (it is the azimuth), ``at_rad`` where its drive holds it from the start."""

    name: str
    plant: PlantParams
    firmware: Firmware
    limits: Limits
    outer: bool
    at_rad: float


class SimDrive(Drive):
    """A simulated drive with its plant and firmware. Deterministic given ``seed``."""

    def __init__(
        self,
        plant: PlantParams,
        *,
        firmware: Firmware | None = None,
        limits: Limits,
        fs_hz: float,
        seed: int,
        serial: str = "SIM-0001",
        has_torque_sensor: bool = True,
        exact_torque_hold: bool = True,
        partner: GimbalPartner | None = None,
        pace: float | None = None,
        link: GimbalLink | None = None,
    ) -> None:
        """``pace``: ``None`` runs each excitation as fast as it computes; a number keeps
        the motion to the wall clock at that multiple of real time (1.0: as a drive does),
        a piece of :data:`PACE_PIECE_S` at a time, so a stop signal lands mid-motion (a
        rehearsal of a station's timing and stops). ``link``: the gimbal (this axis and
        ``partner``) is not simulated here but shared with the partner's own calibration
        (:mod:`hil.drives.shared_gimbal`), which may move it at the same time."""
        if pace is not None and not pace > 0:
            raise ValueError(f"pace must be a positive multiple of real time, not {pace}")
        if link is not None and (partner is None or pace is not None):
            raise ValueError("a shared gimbal needs the partner axis, and runs on its own "
                             "virtual clock (no pace)")
        self._pace = pace
        self._link = link
        self._fs_hz = float(fs_hz)
        if exact_torque_hold and not plant.exact_torque_hold:
            plant = plant.with_changes(exact_torque_hold=True)
        self._plant_params = plant
        firmware = firmware or Firmware()
        self._plant = Plant(plant, fs_hz=fs_hz, seed=seed, firmware=firmware)
        self._partner = partner
        self._gimbal: GimbalPlant | None = None
        if partner is not None and link is None:
            held = Plant(partner.plant.with_changes(exact_torque_hold=exact_torque_hold),
                         fs_hz=fs_hz, seed=seed + (PARTNER_SEED << 32),
                         firmware=partner.firmware, initial_position_rad=partner.at_rad)
            self._held_plant = held
            self._hold_rad = partner.at_rad
            self._gimbal = (GimbalPlant(held, self._plant) if partner.outer
                            else GimbalPlant(self._plant, held))
        if partner is not None:
            self._partner_limits = partner.limits
        moves_elevation = partner is None or partner.name == "elevation"
        follows = partner is not None and partner.name == "elevation"
        self._state = DriveState.DISABLED
        self._envelope = MotionEnvelope.of(limits)
        self._info = DriveInfo(
            vendor="gimbal-hil",
            model="plant_sim",
            firmware_version=firmware.version,
            serial=serial,
            rated_torque_nm=min(plant.torque_limit_nm, limits.torque_nm),
            limits=limits,
            modes=(Mode.TORQUE, Mode.VELOCITY, Mode.POSITION),
            max_sample_rate_hz=fs_hz,
            capabilities=frozenset({Capability.COMPENSATION_TABLE}
                                   | ({Capability.ELEVATION_AXIS} if moves_elevation else set())
                                   | ({Capability.ELEVATION_MOTION} if follows else set())
                                   | ({Capability.TORQUE_SENSOR, Capability.LOCKED_ROTOR}
                                      if has_torque_sensor else set())),
            transport="in-process",
        )

    @property
    def info(self) -> DriveInfo:
        return self._info

    @property
    def plant(self) -> Plant:
        """The simulated axis (not here when the gimbal is shared)."""
        if self._link is not None:
            raise DriveStateError("the shared gimbal's plant lives in its server")
        return self._plant

    def _position(self) -> float:
        return self._link.state().position_rad if self._link else self._plant.position_rad

    def _velocity(self) -> float:
        return self._link.state().velocity_rad_s if self._link else self._plant.velocity_rad_s

    def _other_position(self) -> float:
        if self._link is not None:
            return self._link.state().other_position_rad
        return self._held_plant.position_rad

    def begin_protocol(self, name: str) -> None:
        """On a shared gimbal: wait until ``name`` may run beside the other axis's."""
        if self._link is not None:
            self._link.begin(name)

    def end_protocol(self) -> None:
        if self._link is not None:
            self._link.end()

    def close(self) -> None:
        super().close()
        if self._link is not None:
            self._link.close()

    @contextlib.contextmanager
    def locked_rotor(self) -> Iterator[None]:
        """The rotor clamped through the shaft torque sensor (``load_torque_nm``) inside the
        block, released afterwards (the simulated station's locked-rotor fixture)."""
        if Capability.LOCKED_ROTOR not in self._info.capabilities:
            raise self._without(Capability.LOCKED_ROTOR)
        clamp = self._link or self._plant
        clamp.set_locked_rotor(True)
        try:
            yield
        finally:
            clamp.set_locked_rotor(False)

    def set_elevation(self, elevation_rad: float) -> None:
        """Put the station's elevation axis at ``elevation_rad``: with the gimbal's
        elevation simulated beside this axis, its drive moves it there (a trapezoid at
        :data:`HOLD_SPEED_RAD_S`, :data:`HOLD_ACCEL_RAD_S2`, then :data:`HOLD_SETTLE_S`
        standing) while this axis holds its position; else the plant's parameter is set.

        Raises
        ------
        DriveStateError
            This axis is the gimbal's elevation (no other elevation to move).
        LimitViolationError
            The angle is outside the elevation's travel (nothing moved).
        """
        if self._partner is None:
            self._plant.set_elevation(elevation_rad)
            return
        if self._partner.name != "elevation":
            raise self._without(Capability.ELEVATION_AXIS)
        fs = self._fs_hz
        start = self._other_position()
        path = station_move_rad(start, elevation_rad, fs_hz=fs)
        check_limits(Excitation(name=f"elevation to {elevation_rad:+.4f} rad",
                                mode=Mode.POSITION, command=path, fs_hz=fs),
                     self._partner_limits, start_position_rad=start)
        here = np.full(path.shape, self._position())
        self._step_gimbal(AxisBlock(mode=Mode.POSITION, command=here), held_command=path)
        self._hold_rad = elevation_rad
        log.info("sim: elevation moved to %+.4f rad", self._other_position())

    @property
    def held_text(self) -> str:
        """``elevation (simulated, held by its drive) at +0.6000 rad``: where the gimbal's
        other axis stands."""
        if self._partner is None:
            return ""
        return (f"{self._partner.name} (simulated, held by its drive) at "
                f"{self._other_position():+.4f} rad")

    def load_compensation(self, table: CompensationTable | None) -> None:
        """Load (or clear) the drive's cogging compensation table."""
        drive = self._link or self._plant
        if table is None:
            drive.load_compensation(())
            return
        drive.load_compensation(_harmonics(table.cogging_nm), _harmonics(table.kt_ripple))

    def enable(self) -> None:
        (self._link or self._plant).hold()
        self._state = DriveState.ENABLED

    def disable(self) -> None:
        if self._state is not DriveState.DISABLED:
            log.info("sim: drive disabled (was %s)", self._state.value)
        self._state = DriveState.DISABLED

    def quick_stop(self) -> None:
        """Quick stop: the plant moves only inside :meth:`run` (which ramps it to rest when
        its monitor trips), so between runs the axis already stands."""
        if self._state is DriveState.ENABLED:
            self._state = DriveState.QUICK_STOPPED
            log.info("sim: quick stop, axis at %.3g rad/s", self._velocity())

    def status(self) -> DriveStatus:
        if self._link is not None:
            now = self._link.state()
            return DriveStatus(state=self._state, position_rad=now.position_rad,
                               velocity_rad_s=now.velocity_rad_s)
        return DriveStatus(
            state=self._state,
            position_rad=self._plant.position_rad,
            velocity_rad_s=self._plant.velocity_rad_s,
        )

    def run(self, excitation: Excitation) -> Recording:
        if self._state is not DriveState.ENABLED:
            raise DriveStateError(f"cannot run '{excitation.name}': drive is {self._state.value}")
        if excitation.fs_hz != self._fs_hz:
            raise DriveStateError(
                f"excitation '{excitation.name}' is sampled at {excitation.fs_hz} Hz, "
                f"the simulated drive runs at {self._fs_hz} Hz"
            )
        check_limits(excitation, self._info.limits, start_position_rad=self._position())
        log.info("sim: running %s (%.2f s)", excitation.name, excitation.duration_s)
        envelope = self._envelope
        guard = MotionGuard(position_min_rad=envelope.position_min_rad,
                            position_max_rad=envelope.position_max_rad,
                            velocity_max_rad_s=envelope.velocity_rad_s)
        block = AxisBlock(mode=excitation.mode, command=excitation.command,
                          torque_offset=excitation.torque_offset_nm, guard=guard)
        path = excitation.elevation_path_rad
        if path is not None:
            if Capability.ELEVATION_MOTION not in self._info.capabilities:
                raise self._without(Capability.ELEVATION_MOTION)
            check_limits(replace(excitation, name=f"{excitation.name} (elevation)",
                                 mode=Mode.POSITION, command=path,
                                 torque_offset_nm=None, elevation_path_rad=None),
                         self._partner_limits,
                         start_position_rad=self._other_position())
        try:
            trace, held = self._move(block, path) if self._pace is None else self._paced(
                block, path, pace=self._pace)
        except _PacedStop as stop:  # between two pieces: the axis was moving
            log.info("sim: quick stop, axis at %.3g rad/s", self._velocity())
            self._brake()
            self._state = DriveState.QUICK_STOPPED
            moved, moved_held = stop.so_far
            rows = (self._recording(moved, excitation, moved_held)
                    if len(moved.time_s) else None)
            raise interrupted(stop, rows) from stop
        except KeyboardInterrupt as stop:
            # the kernel runs a whole excitation in one numba call: a signal is handled
            # after it returns, so a stop lands between excitations, with no rows to keep
            self.quick_stop()
            raise interrupted(stop, None) from stop
        if path is not None:
            self._hold_rad = float(path[-1])
        recording = self._recording(trace, excitation, held)
        done = len(trace.time_s)
        if done == len(excitation.command):
            return recording
        # the monitor tripped inside the kernel: the last row is the one that left the envelope
        error = envelope.violation(
            position_rad=float(trace.position_rad[-1]),
            velocity_rad_s=float(trace.velocity_rad_s[-1]),
            time_s=(done - 1) / excitation.fs_hz,
            excitation=excitation.name,
        )
        assert error is not None
        self._brake()
        self._state = DriveState.QUICK_STOPPED
        log.info("sim: %s", error)  # the caller reports the error itself
        error.partial_recording = recording
        raise error

    def _recording(self, trace: PlantTrace, excitation: Excitation,
                   held: PlantTrace | None) -> Recording:
        """The drive's recording of ``trace`` (the elevation's column when it moved too)."""
        metadata = {
            "drive": "plant_sim",
            "excitation": excitation.name,
            "control_mode": excitation.mode.value,
            "serial": self._info.serial,
            **({"held_axes": self.held_text} if self._partner is not None else {}),
            **excitation.metadata,
        }
        recording = trace_to_recording(trace, mode=excitation.mode,
                                       command=excitation.command[:len(trace.time_s)],
                                       metadata=metadata)
        if held is None:
            return recording
        return replace(recording, columns={**recording.columns,
                                           "elevation_rad": held.position_rad})

    def _move(self, block: AxisBlock,
              path: np.ndarray | None) -> tuple[PlantTrace, PlantTrace | None]:
        """This axis through ``block``; the elevation along ``path`` (its trace second)."""
        if path is None:
            return self._advance(block), None
        return self._step_gimbal(block, held_command=path)

    def _paced(self, block: AxisBlock, path: np.ndarray | None, *,
               pace: float) -> tuple[PlantTrace, PlantTrace | None]:
        """:meth:`_move` a piece of :data:`PACE_PIECE_S` at a time, each once the wall
        clock reaches it at ``pace`` × real time.

        Raises
        ------
        _PacedStop
            A stop signal: the pieces moved so far attached.
        """
        fs = self._fs_hz
        size = max(1, round(PACE_PIECE_S * fs))
        offset = block.torque_offset
        started = time.monotonic()
        moved: list[tuple[PlantTrace, PlantTrace | None]] = []
        try:
            for start in range(0, len(block.command), size):
                part = slice(start, start + size)
                piece = AxisBlock(mode=block.mode, command=block.command[part],
                                  torque_offset=None if offset is None or not len(offset)
                                  else offset[part], guard=block.guard)
                moved.append(self._move(piece, None if path is None else path[part]))
                if len(moved[-1][0].time_s) < len(piece.command):
                    break  # the monitor tripped: run() brakes
                time.sleep(max(0.0, started + (start + len(piece.command)) / fs / pace
                               - time.monotonic()))
        except KeyboardInterrupt as stop:
            raise _PacedStop(str(stop), so_far=_joined(moved)) from stop
        return _joined(moved)

    def _brake(self) -> None:
        """The quick-stop ramp: velocity mode from the axis' speed to rest at
        :data:`QUICK_STOP_DECEL_RAD_S2`, then held (unguarded: the axis is already out)."""
        fs = self._fs_hz
        start = self._velocity()
        ramp = max(1, math.ceil(abs(start) / QUICK_STOP_DECEL_RAD_S2 * fs))
        hold = math.ceil(QUICK_STOP_HOLD_S * fs)
        command = np.concatenate([start * (1.0 - np.arange(1, ramp + 1) / ramp), np.zeros(hold)])
        self._advance(AxisBlock(mode=Mode.VELOCITY, command=command))

    def _advance(self, block: AxisBlock) -> PlantTrace:
        """Run this axis through ``block``; the gimbal's other axis, if simulated, holds
        (shared: it does what its own calibration says)."""
        if self._link is not None:
            return self._link.run(block)[0]
        if self._gimbal is None:
            return self._plant.run(block.mode, block.command, block.torque_offset,
                                   guard=block.guard)
        return self._step_gimbal(block, held_command=np.full(block.command.shape,
                                                             self._hold_rad))[0]

    def _step_gimbal(self, block: AxisBlock, *,
                     held_command: np.ndarray) -> tuple[PlantTrace, PlantTrace]:
        """This axis through ``block``, the other following ``held_command`` in position
        mode: (this axis's trace, the other's)."""
        if self._link is not None:
            mine, other = self._link.run(block, held_command)
            assert other is not None
            return mine, other
        assert self._gimbal is not None
        assert self._partner is not None
        held = AxisBlock(mode=Mode.POSITION, command=held_command)
        if self._partner.outer:
            other, mine = self._gimbal.run(held, block)
            return mine, other
        return self._gimbal.run(block, held)


def station_move_rad(start_rad: float, target_rad: float, *, fs_hz: float) -> np.ndarray:
    """How the simulated station moves a held axis: a trapezoid at :data:`HOLD_SPEED_RAD_S`
    and :data:`HOLD_ACCEL_RAD_S2`, then :data:`HOLD_SETTLE_S` standing (one command per
    control period)."""
    path = trapezoid_rad(start_rad, target_rad, speed_rad_s=HOLD_SPEED_RAD_S,
                         accel_rad_s2=HOLD_ACCEL_RAD_S2, step_s=1.0 / fs_hz)
    return np.concatenate([path, np.full(math.ceil(HOLD_SETTLE_S * fs_hz), target_rad)])


class _PacedStop(KeyboardInterrupt):
    """A stop signal between two paced pieces, with the traces moved so far."""

    def __init__(self, message: str, *,
                 so_far: tuple[PlantTrace, PlantTrace | None]) -> None:
        super().__init__(message)
        self.so_far = so_far


Moved = tuple[PlantTrace, PlantTrace | None]  # this axis's trace, the elevation's if it moved


def _joined(pieces: list[Moved]) -> Moved:
    """The traces of consecutive pieces as one (empty when there are none)."""
    mine = concatenate_traces([axis for axis, _ in pieces])
    held = [other for _, other in pieces if other is not None]
    return mine, concatenate_traces(held) if held else None


def _harmonics(table: tuple[PositionHarmonic, ...]) -> tuple[Harmonic, ...]:
    return tuple(Harmonic(order=h.order, amplitude=h.amplitude, phase_rad=h.phase_rad)
                 for h in table)
