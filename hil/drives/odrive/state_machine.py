"""The ODrive axis state machine over CANSimple: IDLE ⇄ CLOSED_LOOP_CONTROL with error
clearing, control-mode selection, the hold command, quick stop and the contract's status.

Every state change is confirmed by a heartbeat sent after the request (the ODrive has no
other way to report its state over CANSimple); an axis error is a
:class:`DriveFaultError` naming the firmware's error flags and its disarm reason. The
control mode cannot be read back over CANSimple (only through the firmware's endpoint
table by SDO); the mode is set before each enable and each run.

Quick stop: the velocity loop brakes the axis to rest (velocity control, input 0), then
IDLE; what cannot be confirmed ends in Estop, which disarms the ODrive at once.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from hil.drives.base import DriveState, DriveStatus
from hil.drives.odrive.link import Feedback, OdriveLink
from hil.drives.odrive.protocol import (
    AxisState,
    Cmd,
    ControlMode,
    InputMode,
    decode_u32_pair,
    encode_float,
    encode_float_pair,
    encode_input_pos,
    encode_u32,
    encode_u32_pair,
    error_names,
    rad,
    turns,
)
from hil.errors import DriveCommunicationError, DriveError, DriveFaultError, DriveStateError
from hil.motion import Mode

log = logging.getLogger(__name__)

REST_RAD_S = 0.05  # a quick stop is done below this speed (the estimate's noise: ~0.01)
REST_S = 0.05  # ... held this long (the brake overshoots through zero)
LOCKSTEP_RETRIES = 3  # periods stepped for one feedback set before the link is lost
CONTROL_MODES = {Mode.VELOCITY: ControlMode.VELOCITY_CONTROL,
                 Mode.TORQUE: ControlMode.TORQUE_CONTROL,
                 Mode.POSITION: ControlMode.POSITION_CONTROL}


def setpoint(mode: Mode, value_si: float, torque_ff_nm: float = 0.0) -> tuple[int, bytes]:
    """The Set_Input_* frame of ``mode``'s setpoint ``value_si`` (rad/s, N·m or rad), with
    the torque feed-forward (velocity and position modes)."""
    if mode is Mode.VELOCITY:
        return Cmd.SET_INPUT_VEL, encode_float_pair(turns(value_si), torque_ff_nm)
    if mode is Mode.TORQUE:
        return Cmd.SET_INPUT_TORQUE, encode_float(value_si) + bytes(4)
    return Cmd.SET_INPUT_POS, encode_input_pos(turns(value_si), 0.0, torque_ff_nm)


class OdriveStateMachine:
    """Power state and control mode of one ODrive axis.

    Attributes
    ----------
    state : DriveState
        The state the contract last put the axis in.
    mode : Mode or None
        The control mode selected last.
    """

    def __init__(self, link: OdriveLink) -> None:
        self.link = link
        self.station = link.station
        self.state = DriveState.DISABLED
        self.mode: Mode | None = None

    # -- time --------------------------------------------------------------------------------
    def tick(self) -> Feedback:
        """The next feedback period (in lockstep the host steps it with its hold command).

        Raises
        ------
        DriveCommunicationError
            No feedback set within ``frame_timeout_s``.
        """
        link = self.link
        if not link.lockstep:
            feedback = link.next_feedback()
        else:  # a period whose set was lost: step once or twice more
            for _ in range(LOCKSTEP_RETRIES):
                link.step()
                feedback = link.lockstep_feedback()
                if feedback is not None:
                    break
        if feedback is None:
            raise DriveCommunicationError(
                f"{link.where}: no feedback (encoder, Iq, torques) for "
                f"{self.station.frame_timeout_s:g} s (frame_timeout_s in {self.station.source})")
        return feedback

    def _await(self, what: str, done: Callable[[], bool], timeout_s: float) -> None:
        """Tick until ``done()``; past ``timeout_s`` of the drive's clock: DriveStateError."""
        start = self.link.drive_time_s()
        while not done():
            self.tick()
            if self.link.drive_time_s() - start > timeout_s:
                beat = self.link.heartbeat
                seen = "none" if beat is None else (
                    f"state {_state_name(beat.axis_state)}, axis error "
                    f"{error_names(beat.axis_error)}")
                raise DriveStateError(f"{self.link.where}: {what} not confirmed within "
                                      f"{timeout_s:g} s (last heartbeat: {seen})")

    def _request_state(self, state: AxisState, timeout_s: float) -> None:
        """Request ``state`` and wait for a later heartbeat showing it (or an axis error)."""
        link = self.link
        before = link.heartbeats
        link.send(Cmd.SET_AXIS_STATE, encode_u32(state) + bytes(4))

        def done() -> bool:
            beat = link.heartbeat
            return (link.heartbeats > before and beat is not None
                    and (beat.axis_state == state or beat.axis_error != 0))

        self._await(f"axis state {state.name}", done, timeout_s)

    # -- the contract ------------------------------------------------------------------------
    def status(self) -> DriveStatus:
        """State (from the heartbeat), position and velocity (a fresh feedback set)."""
        feedback = self.tick()
        beat = self.link.heartbeat
        error = 0 if beat is None else beat.axis_error
        if error:
            state = DriveState.FAULT
        elif beat is not None and beat.axis_state == AxisState.CLOSED_LOOP_CONTROL:
            state = DriveState.ENABLED
        elif self.state is DriveState.QUICK_STOPPED:
            state = DriveState.QUICK_STOPPED
        else:
            state = DriveState.DISABLED
        return DriveStatus(state=state, position_rad=rad(feedback.position_turns),
                           velocity_rad_s=rad(feedback.velocity_turns_s),
                           fault_code=error if error else None)

    def enable(self, mode: Mode) -> None:
        """Clear errors, select ``mode`` holding the axis, request CLOSED_LOOP_CONTROL.

        Raises
        ------
        DriveFaultError
            An axis error that does not clear, or one raised while entering closed loop.
        DriveStateError
            Closed loop not confirmed by a heartbeat within ``state_timeout_s``.
        """
        link = self.link
        link.stop_feeding()
        self.tick()
        beat = link.heartbeat
        if beat is not None and beat.axis_error:
            code = beat.axis_error
            before = link.heartbeats
            link.send(Cmd.CLEAR_ERRORS, b"\0")
            link.errors = None  # a Get_Error sent before the clear is stale
            self._await("clearing the axis errors", lambda: link.heartbeats > before,
                        self.station.state_timeout_s)
            self.raise_if_faulted("that Clear_Errors did not clear")
            log.info("%s: axis error %s cleared", link.where, error_names(code))
        self.select(mode)
        self._request_state(AxisState.CLOSED_LOOP_CONTROL, self.station.state_timeout_s)
        self.raise_if_faulted("while entering closed loop")
        self.state = DriveState.ENABLED
        link.feed_while_idle()

    def select(self, mode: Mode) -> None:
        """Set the control mode (input passthrough) and the hold command of ``mode``."""
        self.link.send(Cmd.SET_CONTROLLER_MODE,
                       encode_u32_pair(CONTROL_MODES[mode], InputMode.PASSTHROUGH))
        self.hold(mode)
        self.mode = mode

    def hold(self, mode: Mode) -> None:
        """Command the axis to stay: zero velocity or torque, or where it is."""
        value = 0.0
        if mode is Mode.POSITION:
            latest = self.link.latest if self.link.latest is not None else self.tick()
            value = rad(latest.position_turns)
        self.link.command(*setpoint(mode, value))

    def fault(self, context: str) -> DriveFaultError | None:
        """The axis error the last heartbeat shows, as an error (None: no error)."""
        beat = self.link.heartbeat
        if beat is None or not beat.axis_error:
            return None
        why = ""
        try:
            active, disarm = decode_u32_pair(self.link.request(Cmd.GET_ERROR))
            why = f"; active errors {error_names(active)}, disarm reason {error_names(disarm)}"
        except DriveError:
            pass
        self.state = DriveState.FAULT
        return DriveFaultError(f"{self.link.where}: axis error {error_names(beat.axis_error)} "
                               f"{context}{why}", code=beat.axis_error)

    def raise_if_faulted(self, context: str) -> None:
        """Raise the axis error the last heartbeat shows."""
        error = self.fault(context)
        if error is not None:
            raise error

    def disable(self) -> None:
        """Request IDLE, confirmed by a heartbeat; Estop when it cannot be. Logs, never
        raises a DriveError."""
        self.link.stop_feeding()
        try:
            self._request_state(AxisState.IDLE, self.station.state_timeout_s)
            if self.state is not DriveState.DISABLED:
                log.info("%s: axis IDLE", self.link.where)
        except DriveError as exc:
            log.error("%s: IDLE not confirmed (%s): Estop", self.link.where, exc)
            self.estop()
        self.state = DriveState.DISABLED

    def quick_stop(self) -> None:
        """Brake to rest by the velocity loop, then IDLE; Estop when that cannot be
        confirmed. Logs, never raises a DriveError."""
        link = self.link
        link.stop_feeding()
        try:
            beat = link.heartbeat
            if beat is not None and beat.axis_state == AxisState.CLOSED_LOOP_CONTROL:
                self.select(Mode.VELOCITY)

                still_since: list[float] = []

                def at_rest() -> bool:  # below REST_RAD_S for REST_S (not a zero crossing)
                    latest = link.latest
                    if latest is None or abs(rad(latest.velocity_turns_s)) >= REST_RAD_S:
                        still_since.clear()
                        return False
                    if not still_since:
                        still_since.append(link.drive_time_s())
                    return link.drive_time_s() - still_since[0] >= REST_S

                self.tick()
                self._await("quick stop (at rest)", at_rest, self.station.quick_stop_timeout_s)
            self._request_state(AxisState.IDLE, self.station.state_timeout_s)
            log.info("%s: quick-stopped, IDLE", link.where)
        except DriveError as exc:
            log.error("%s: quick stop not confirmed (%s): Estop", link.where, exc)
            self.estop()
        self.state = DriveState.QUICK_STOPPED

    def estop(self) -> None:
        """Estop: the ODrive disarms at once (its axis error then says ESTOP_REQUESTED)."""
        try:
            self.link.send(Cmd.ESTOP)
        except DriveError as exc:
            log.error("%s: Estop could not be sent: %s", self.link.where, exc)

    def make_safe(self, error: DriveError) -> None:
        """After a failed run: quick stop (braked, then IDLE), IDLE confirmed."""
        if isinstance(error, DriveFaultError):
            self.state = DriveState.FAULT
        self.quick_stop()
        self.disable()


def _state_name(value: int) -> str:
    try:
        return AxisState(value).name
    except ValueError:
        return str(value)
