"""One ODrive axis (firmware 0.6.x CANSimple) on a python-can bus, backed by :mod:`plant_sim`.

It answers as a 0.6 firmware does, as far as the harness uses it: the heartbeat and the
cyclic feedback messages (Get_Encoder_Estimates, Get_Iq, Get_Torques; Get_Error when its
period is set) at the configured periods; remote-frame requests of Get_Version, Address,
Get_Error and the feedback messages; Set_Axis_State (IDLE, CLOSED_LOOP_CONTROL; closed loop
refused while an error is active), Set_Controller_Mode (torque, velocity, position control,
passthrough input), Set_Input_Vel with its torque feed-forward, Set_Input_Torque,
Set_Input_Pos, Set_Limits (its velocity limit trips VELOCITY_LIMIT_VIOLATION beyond 1.2×, the
firmware's default tolerance), Clear_Errors, Estop (ESTOP_REQUESTED). An axis error disarms:
the axis goes IDLE, the heartbeat carries the error. With a watchdog timeout (realtime
only) a closed-loop axis whose setpoints stop for that long trips WATCHDOG_TIMER_EXPIRED.

Feedback of a period: the plant's last control-loop sample of it (position measured at the
start of that control period, velocity estimate); Torque_Target the torque commanded over
it, Iq_Measured the plant's measured q-axis current, Torque_Estimate = K_t·Iq_Measured and
Iq_Setpoint = Torque_Target/K_t, with the drive's nominal K_t (the plant's
``torque_constant_nm_a``; the true one differs by ``torque_constant_error_rel``).

**Pacing.** ``"realtime"``: a thread advances the plant half a feedback period per half
period of the wall clock, each half with the setpoints received before it, and sends what
falls due at each full period, like the ODrive's own timer. ``"lockstep"`` (the emulator
only, for fast tests; a real ODrive has no such mode): CANSimple has no SYNC, so the
emulator advances one feedback period (``feedback_period_ms × fs`` control periods of the
plant) for each setpoint message (Set_Input_*) the host sends and answers with that
period's messages; with nothing sent, no time passes. The setpoint takes effect at the
middle of its period, where a host that answers each feedback set half a period later puts
it on a real bus (:mod:`hil.drives.odrive.acquire`). Runs go as fast as the frames.

Fault injection (:class:`OdriveFaults`): an axis error at a time, the heartbeat stopping
while the feedback goes on, a feedback message dropped every n periods, a node gone silent.

It knows nothing about the backend that talks to it.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import math
import threading
import time
from dataclasses import dataclass
from typing import Any

import can
import numpy as np

from hil.drives.odrive.protocol import (
    AxisState,
    Cmd,
    ControlMode,
    Heartbeat,
    OdriveError,
    ProcedureResult,
    Version,
    arbitration_id,
    decode_float,
    decode_float_pair,
    decode_input_pos,
    decode_u32,
    decode_u32_pair,
    encode_address,
    encode_float_pair,
    encode_heartbeat,
    encode_u32_pair,
    encode_version,
    rad,
    split_id,
    turns,
)
from hil.motion import Mode
from plant_sim.firmware import Firmware
from plant_sim.model import Plant
from plant_sim.params import PlantParams

log = logging.getLogger(__name__)

VEL_LIMIT_TOLERANCE = 1.2  # controller.config.vel_limit_tolerance's default
DEFAULT_VEL_LIMIT_TURNS_S = 2.0  # controller.config.vel_limit's default
FIRMWARE_VERSION = (0, 6, 10)


@dataclass(slots=True)
class _Inputs:
    """The controller's setpoints (SI units)."""

    vel_rad_s: float = 0.0
    torque_nm: float = 0.0
    pos_rad: float = 0.0
    torque_ff_nm: float = 0.0


@dataclass(frozen=True, slots=True, kw_only=True)
class OdriveFaults:
    """Faults the emulated ODrive injects (times: plant time in closed loop)."""

    axis_error_after_s: float | None = None
    axis_error: int = int(OdriveError.DRV_FAULT)
    heartbeat_stops_after_s: float | None = None
    drop_torques_every: int = 0  # in closed loop, every n-th period's Get_Torques not sent
    silent_after_s: float | None = None
    late_frames_every: int = 0  # every n-th period's messages go out late_frames_s late
    late_frames_s: float = 0.0  # (the node or the bus busy: wall clock only)


class OdriveEmulator:
    """One emulated ODrive axis (module docstring).

    Parameters
    ----------
    plant : PlantParams
        The axis.
    firmware : Firmware or None
        The controller the plant runs (gains, filter, current loop).
    fs_hz : float
        The control rate of the plant.
    seed : int
        The plant's noise seed.
    channel, interface : str
        The python-can bus (a private ``virtual`` channel in the tests).
    node_id : int
        CANSimple node id.
    pacing : str
        ``"realtime"`` or ``"lockstep"``.
    feedback_period_ms, heartbeat_period_ms, error_period_ms : int
        The cyclic messages' periods (0: off; the feedback's must be positive).
    """

    def __init__(
        self,
        plant: PlantParams,
        *,
        firmware: Firmware | None = None,
        fs_hz: float,
        seed: int,
        channel: str,
        interface: str = "virtual",
        node_id: int = 0,
        pacing: str = "lockstep",
        feedback_period_ms: int = 2,
        heartbeat_period_ms: int = 100,
        error_period_ms: int = 0,
        serial_number: int = 0x3A5F0001,
        watchdog_timeout_s: float = 0.0,
        faults: OdriveFaults | None = None,
    ) -> None:
        self.firmware = firmware or Firmware()
        self.plant = Plant(plant, fs_hz=fs_hz, seed=seed, firmware=self.firmware)
        self.fs_hz = float(fs_hz)
        self.kt_nm_a = plant.torque_constant_nm_a
        self.channel, self.interface = channel, interface
        self.node_id = node_id
        self.pacing = pacing
        steps = feedback_period_ms * 1e-3 * self.fs_hz
        if feedback_period_ms <= 0 or abs(steps - round(steps)) > 1e-9:
            raise ValueError(f"feedback period {feedback_period_ms} ms is not a whole number "
                             f"of control periods at {fs_hz:g} Hz")
        self.steps_per_period = round(steps)
        self.heartbeat_steps = round(heartbeat_period_ms * 1e-3 * self.fs_hz)
        self.error_steps = round(error_period_ms * 1e-3 * self.fs_hz)
        self.serial_number = serial_number
        self.watchdog_timeout_s = watchdog_timeout_s
        self.faults = faults or OdriveFaults()
        self.axis_state = AxisState.IDLE
        self.control_mode = ControlMode.VELOCITY_CONTROL
        self.input_mode = 1
        self.procedure_result = ProcedureResult.SUCCESS
        self.active_errors = 0
        self.disarm_reason = 0
        self.vel_limit_turns_s = DEFAULT_VEL_LIMIT_TURNS_S
        self.current_limit_a = math.inf
        self.inputs = _Inputs()  # the setpoints the controller runs on
        self.received = _Inputs()  # the latest ones received (taken at the next half period)
        self.closed_loop_s = 0.0  # plant time spent in closed loop (fault times)
        self.periods = 0  # feedback periods run
        self.setpoints = 0  # Set_Input_* messages received
        self._tripped = False  # the injected axis error, once
        self._steps_done = 0
        self._last_feed = time.monotonic()
        self._latched = (0.0, 0.0, 0.0, 0.0)  # position, velocity, torque target, Iq measured
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._stopping = threading.Event()
        self._threads: list[threading.Thread] = []
        self._bus: Any = None
        self._epoch_s = 0.0  # wall-clock time of plant step 0 (realtime frame stamps)

    # -- life cycle ------------------------------------------------------------------------
    def start(self) -> None:
        # the plant's compiled kernel (numba, cached on disk) compiles at its first run:
        # done on a copy before going on the bus, the plant itself untouched
        copy.deepcopy(self.plant).run(Mode.TORQUE, np.zeros(1))
        self._latch(self.plant.run(Mode.TORQUE, np.zeros(1)))
        options: dict[str, Any] = ({"preserve_timestamps": True}
                                   if self.interface == "virtual" else {})
        self._bus = can.Bus(interface=self.interface, channel=self.channel,
                            receive_own_messages=False, **options)
        self._epoch_s = time.time() - self._steps_done / self.fs_hz
        self._stopping.clear()
        self._threads = [threading.Thread(target=self._serve, name="odrive-emulator-rx",
                                          daemon=True)]
        if self.pacing == "realtime":
            self._threads.append(threading.Thread(target=self._clock, name="odrive-emulator-clock",
                                                  daemon=True))
        for thread in self._threads:
            thread.start()
        self._send(Cmd.HEARTBEAT, self._heartbeat())  # at power-on
        log.info("ODrive emulator node %d up on %s (%s)", self.node_id, self.channel, self.pacing)

    def stop(self) -> None:
        self._stopping.set()
        for thread in self._threads:
            thread.join(5)
        self._threads = []
        if self._bus is not None:
            self._bus.shutdown()
            self._bus = None

    def __enter__(self) -> OdriveEmulator:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- the bus ---------------------------------------------------------------------------
    def _send(self, cmd: int, data: bytes, stamp_s: float | None = None) -> None:
        """One frame, stamped ``stamp_s`` (its period's end on the emulated ODrive's clock)
        or now: on python-can's virtual bus the stamp travels with the frame, as a real
        interface's receive stamp shows the ODrive's timer, not the emulator thread's lag."""
        bus = self._bus
        if bus is None:
            return
        message = can.Message(arbitration_id=arbitration_id(self.node_id, cmd), data=data,
                              is_extended_id=False,
                              timestamp=time.time() if stamp_s is None else stamp_s)
        with self._send_lock:
            bus.send(message)

    def _serve(self) -> None:
        while not self._stopping.is_set():
            message = self._bus.recv(0.05)
            if message is None or message.is_error_frame:
                continue
            node, cmd = split_id(message.arbitration_id)
            if node != self.node_id or message.is_extended_id:
                continue
            if message.is_remote_frame:
                self._answer(cmd)
                continue
            step = self._on_command(cmd, bytes(message.data))
            if step and self.pacing == "lockstep":
                self._period()

    def _clock(self) -> None:
        half_s = self.steps_per_period / self.fs_hz / 2
        due = time.monotonic() + half_s
        while not self._stopping.is_set():
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            self._period()
            due += 2 * half_s
            if time.monotonic() - due > 20 * half_s:  # the emulator was not scheduled
                due = time.monotonic() + half_s

    def _silent(self) -> bool:
        after = self.faults.silent_after_s
        return after is not None and self.closed_loop_s >= after

    def _answer(self, cmd: int) -> None:
        if self._silent():
            return
        with self._lock:
            data = self._message(cmd)
        if data is not None:
            self._send(cmd, data)

    def _message(self, cmd: int) -> bytes | None:
        """The payload of ``cmd``'s message now (None: not served). Call with the lock."""
        position, velocity, target, iq = self._latched
        if cmd == Cmd.GET_VERSION:
            major, minor, revision = FIRMWARE_VERSION
            return encode_version(Version(2, 4, 0, 0, major, minor, revision, 0))
        if cmd == Cmd.ADDRESS:
            return encode_address(self.node_id, self.serial_number)
        if cmd == Cmd.HEARTBEAT:
            return self._heartbeat()
        if cmd == Cmd.GET_ERROR:
            return encode_u32_pair(self.active_errors, self.disarm_reason)
        if cmd == Cmd.GET_ENCODER_ESTIMATES:
            return encode_float_pair(turns(position), turns(velocity))
        if cmd == Cmd.GET_IQ:
            return encode_float_pair(target / self.kt_nm_a, iq)
        if cmd == Cmd.GET_TORQUES:
            return encode_float_pair(target, self.kt_nm_a * iq)
        return None

    def _heartbeat(self) -> bytes:
        return encode_heartbeat(Heartbeat(self.active_errors, int(self.axis_state),
                                          int(self.procedure_result), True))

    # -- commands ----------------------------------------------------------------------------
    def _on_command(self, cmd: int, data: bytes) -> bool:
        """Apply one command; True for a setpoint (a lockstep period follows)."""
        with self._lock:
            if cmd == Cmd.SET_AXIS_STATE:
                self._request_state(decode_u32(data))
            elif cmd == Cmd.SET_CONTROLLER_MODE:
                mode, self.input_mode = decode_u32_pair(data)
                if mode == ControlMode.POSITION_CONTROL != self.control_mode:
                    self.inputs.pos_rad = self.received.pos_rad = self._latched[0]
                self.control_mode = ControlMode(mode)
            elif cmd == Cmd.SET_INPUT_VEL:
                vel, self.received.torque_ff_nm = decode_float_pair(data)
                self.received.vel_rad_s = rad(vel)
            elif cmd == Cmd.SET_INPUT_TORQUE:
                self.received.torque_nm = decode_float(data)
            elif cmd == Cmd.SET_INPUT_POS:
                pos, _, self.received.torque_ff_nm = decode_input_pos(data)
                self.received.pos_rad = rad(pos)
            elif cmd == Cmd.SET_LIMITS:
                self.vel_limit_turns_s, self.current_limit_a = decode_float_pair(data)
            elif cmd == Cmd.CLEAR_ERRORS:
                self.active_errors = self.disarm_reason = 0
            elif cmd == Cmd.ESTOP:
                self._error(OdriveError.ESTOP_REQUESTED)
            setpoint = cmd in (Cmd.SET_INPUT_VEL, Cmd.SET_INPUT_TORQUE, Cmd.SET_INPUT_POS)
            if setpoint:
                self.setpoints += 1
                self._last_feed = time.monotonic()
            return setpoint

    def _request_state(self, requested: int) -> None:
        if requested == AxisState.IDLE:
            self.axis_state = AxisState.IDLE
            self.procedure_result = ProcedureResult.SUCCESS
        elif requested == AxisState.CLOSED_LOOP_CONTROL:
            if self.active_errors:
                self.procedure_result = ProcedureResult.DISARMED
                return
            if self.axis_state != AxisState.CLOSED_LOOP_CONTROL:
                self.plant.hold()
                # closed loop starts holding where the axis is
                self.inputs = _Inputs(pos_rad=self._latched[0])
                self.received = _Inputs(pos_rad=self._latched[0])
                self._last_feed = time.monotonic()
            self.axis_state = AxisState.CLOSED_LOOP_CONTROL
            self.procedure_result = ProcedureResult.SUCCESS
        else:  # calibration and the rest: not emulated
            self.procedure_result = ProcedureResult.CANCELLED

    def _error(self, code: int) -> None:
        if not self.active_errors:
            log.info("ODrive emulator: axis error 0x%X", code)
        self.active_errors |= code
        self.disarm_reason = code
        self.axis_state = AxisState.IDLE

    # -- time ----------------------------------------------------------------------------------
    def _period(self) -> None:
        """One feedback period of the plant, the setpoints received taken at its middle
        (in realtime: each half period sleeps first), then the messages that fall due."""
        first = self.steps_per_period // 2
        self._advance(first)
        if self.pacing == "realtime":
            time.sleep(first / self.fs_hz)
        with self._lock:
            self.inputs = dataclasses.replace(self.received)
        self._advance(self.steps_per_period - first)
        with self._lock:
            self.periods += 1
            frames = self._due(self._steps_done - self.steps_per_period, self._steps_done)
            stamp_s = self._epoch_s + self._steps_done / self.fs_hz
        every = self.faults.late_frames_every
        if every and self.periods % every == 0:
            time.sleep(self.faults.late_frames_s)
        for cmd, data in frames:
            self._send(cmd, data, stamp_s if self.pacing == "realtime" else None)

    def _advance(self, steps: int) -> None:
        with self._lock:
            if steps <= 0:
                return
            closed = self.axis_state == AxisState.CLOSED_LOOP_CONTROL
            mode, command, offset = self._command(steps, closed)
            trace = self.plant.run(mode, command, offset)
            self._latch(trace)
            self._steps_done += steps
            if closed:
                self.closed_loop_s += steps / self.fs_hz
                self._check(trace)

    def _command(self, steps: int, closed: bool) -> tuple[Mode, np.ndarray, np.ndarray | None]:
        if not closed:
            return Mode.TORQUE, np.zeros(steps), None
        inputs = self.inputs
        offset = np.full(steps, inputs.torque_ff_nm)
        if self.control_mode == ControlMode.TORQUE_CONTROL:
            return Mode.TORQUE, np.full(steps, inputs.torque_nm), None
        if self.control_mode == ControlMode.POSITION_CONTROL:
            return Mode.POSITION, np.full(steps, inputs.pos_rad), offset
        return Mode.VELOCITY, np.full(steps, inputs.vel_rad_s), offset

    def _latch(self, trace: Any) -> None:
        self._latched = (float(trace.position_rad[-1]), float(trace.velocity_rad_s[-1]),
                         float(trace.torque_nm[-1]), float(trace.current_a[-1]))

    def _check(self, trace: Any) -> None:
        """The firmware's checks after a closed-loop period, and the injected faults."""
        limit = rad(self.vel_limit_turns_s) * VEL_LIMIT_TOLERANCE
        if float(np.max(np.abs(trace.velocity_rad_s))) > limit:
            self._error(OdriveError.VELOCITY_LIMIT_VIOLATION)
        after = self.faults.axis_error_after_s
        if after is not None and not self._tripped and self.closed_loop_s >= after:
            self._tripped = True
            self._error(self.faults.axis_error)
        if (self.pacing == "realtime" and self.watchdog_timeout_s
                and time.monotonic() - self._last_feed > self.watchdog_timeout_s):
            self._error(OdriveError.WATCHDOG_TIMER_EXPIRED)

    def _due(self, before: int, after: int) -> list[tuple[int, bytes]]:
        """The cyclic messages whose period boundary lies in (before, after]."""
        if self._silent():
            return []
        frames: list[tuple[int, bytes]] = []
        stops = self.faults.heartbeat_stops_after_s
        beating = stops is None or self.closed_loop_s < stops
        if beating and self.heartbeat_steps and after // self.heartbeat_steps > before // \
                self.heartbeat_steps:
            frames.append((Cmd.HEARTBEAT, self._heartbeat()))
        if self.error_steps and after // self.error_steps > before // self.error_steps:
            frames.append((Cmd.GET_ERROR, encode_u32_pair(self.active_errors,
                                                          self.disarm_reason)))
        drop = self.faults.drop_torques_every
        dropping = drop and self.axis_state == AxisState.CLOSED_LOOP_CONTROL
        for cmd in (Cmd.GET_ENCODER_ESTIMATES, Cmd.GET_IQ, Cmd.GET_TORQUES):
            if cmd == Cmd.GET_TORQUES and dropping and self.periods % drop == 0:
                continue
            data = self._message(cmd)
            assert data is not None
            frames.append((cmd, data))
        return frames
