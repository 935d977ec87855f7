"""OdriveDrive: the Drive contract over ODrive's CANSimple (firmware 0.6.x), streamed at
the rate of the ODrive's cyclic feedback messages.

Bring-up, in order: the bus opened (filtered to the node), a first heartbeat awaited, the
identity asked for (Get_Version; Address for the serial, where the firmware answers it),
Set_Limits sent (velocity limit: the motion monitor's envelope; current limit: the unit's
torque limit over the station's K_t, or ``current_limit_a``), the cyclic messages
measured against the station's periods (each feedback message once a period, the
heartbeat at its period; a mismatch is refused in one line naming the station's key and
the odrivetool setting), and the axis put in IDLE. ``info.max_sample_rate_hz`` is the
feedback rate; no drive recorder.

The ODrive has no position limits over CANSimple: the host's motion monitor
(:class:`MotionEnvelope`, every row) is the only one; the ODrive's own velocity limit
trips it out of closed loop (VELOCITY_LIMIT_VIOLATION) beyond its tolerance. The axis is
left IDLE on close and after every failed run.
"""

from __future__ import annotations

import logging

import numpy as np

from hil.drives.base import (
    Drive,
    DriveInfo,
    DriveState,
    DriveStatus,
    MotionEnvelope,
    check_limits,
    interrupted,
)
from hil.drives.odrive.acquire import (
    StreamedRun,
    decimation,
    late_commands,
    stream,
    to_recording,
)
from hil.drives.odrive.link import OdriveLink
from hil.drives.odrive.protocol import (
    AxisState,
    Cmd,
    decode_address,
    decode_version,
    encode_float_pair,
    turns,
)
from hil.drives.odrive.state_machine import OdriveStateMachine
from hil.drives.odrive.station import OdriveStation
from hil.drives.realtime import collector_held
from hil.errors import DriveCommunicationError, DriveError, DriveStateError, ProfileError
from hil.motion import Excitation, Limits, Mode
from hil.recording import Recording

log = logging.getLogger(__name__)

RATE_TOLERANCE = 0.1  # a measured message period this far from the declared one is refused
CURRENT_LIMIT_MARGIN = 1.25  # above the unit's torque limit over K_t (the loops' overshoot)
RATE_WINDOW_PERIODS = 2.5  # heartbeat periods the bring-up measures over
INCOMPLETE_FRACTION = 0.1  # of the periods measured: feedback sets missing a message


class OdriveDrive(Drive):
    """One ODrive axis on a CAN bus.

    Parameters
    ----------
    station : OdriveStation
        Bus, node id, message periods, timeouts, pacing, K_t.
    limits : Limits
        The unit's envelope, refused before motion.

    Raises
    ------
    DriveCommunicationError
        The bus cannot be opened or the node does not answer.
    ProfileError
        The ODrive's cyclic messages are not the station's, or the station declares
        equipment the backend does not serve.
    """

    def __init__(self, station: OdriveStation, *, limits: Limits) -> None:
        equipment = station.equipment
        if equipment.torque_transducer is not None or equipment.locked_rotor is not None:
            table = ("[torque_transducer]" if equipment.torque_transducer is not None
                     else "[locked_rotor]")
            raise ProfileError(f"{table} is not served over an ODrive (CANSimple has no output "
                               "for a clamp, and K_t is measured only with both): remove it",
                               source=station.source)
        self.station = station
        self.limits = limits
        self.link = OdriveLink(station)
        self.states = OdriveStateMachine(self.link)
        self.link.open()
        try:
            self._info = self._bring_up()
        except BaseException:
            self.link.close()
            raise

    # -- bring-up ----------------------------------------------------------------------------
    def _bring_up(self) -> DriveInfo:
        link, st = self.link, self.station
        version = decode_version(link.request(Cmd.GET_VERSION))
        serial = "unknown"
        try:
            node, number = decode_address(link.request(Cmd.ADDRESS))
            serial = f"{number:012X}" if node == st.node_id else serial
        except DriveCommunicationError:
            log.info("%s: no answer to Address: serial unknown", link.where)
        current_limit = st.current_limit_a or (
            self.limits.torque_nm / st.torque_constant_nm_a * CURRENT_LIMIT_MARGIN)
        envelope = MotionEnvelope.of(self.limits)
        link.send(Cmd.SET_LIMITS, encode_float_pair(turns(envelope.velocity_rad_s),
                                                    current_limit))
        self._measure_rates()
        beat = link.heartbeat
        if beat is not None and beat.axis_state != AxisState.IDLE:
            log.warning("%s: found in state %d: IDLE requested", link.where, beat.axis_state)
            self.states.disable()
        return DriveInfo(
            vendor="ODrive Robotics",
            model=f"ODrive (hardware {version.hardware})",
            firmware_version=version.firmware,
            serial=serial,
            rated_torque_nm=self.limits.torque_nm,
            limits=self.limits,
            modes=(Mode.VELOCITY, Mode.TORQUE, Mode.POSITION),
            max_sample_rate_hz=1.0 / st.feedback_period_s,
            timing={"torque_sample": "instantaneous",
                    "control_period_s": f"{st.control_period_s:g}",
                    "torque_reports": ("demand" if st.torque_source == "target"
                                       else "measured_current"),
                    "position_latch": "unknown",
                    "command_interpolation": "hold",
                    "object_map": f"CANSimple {version.firmware}"},
            transport=f"odrive cansimple {st.interface} {st.channel} node {st.node_id}"
                      + (" (lockstep emulator)" if link.lockstep else ""),
        )

    def _measure_rates(self) -> None:
        """Watch the cyclic messages for a few heartbeat periods: one feedback set each
        feedback period and heartbeats at theirs, else a ProfileError naming the key."""
        link, st = self.link, self.station
        window_s = RATE_WINDOW_PERIODS * st.heartbeat_period_ms * 1e-3
        if not link.lockstep:
            link.drain()
        first = self.states.tick()
        beats, start = link.heartbeats, link.drive_time_s()
        stamps = [first.stamp_s]
        beat_times: list[float] = []
        while link.drive_time_s() - start < window_s:
            before = link.heartbeats
            stamps.append(self.states.tick().stamp_s)
            if link.heartbeats > before:
                beat_times.append(link.drive_time_s())
        if link.heartbeat is None or link.heartbeats == beats:
            raise ProfileError(
                f"[odrive] heartbeat_period_ms = {st.heartbeat_period_ms}: {link.where} sent "
                f"no heartbeat in {window_s:g} s (odrivetool: axis0.config.can."
                f"heartbeat_msg_rate_ms = {st.heartbeat_period_ms})", source=st.source)
        if link.lockstep:
            feedback_s = (link.drive_time_s() - start) / max(len(stamps) - 1, 1)
        else:
            feedback_s = float(np.median(np.diff(stamps)))
        self._refuse_period("encoder_period_ms", st.encoder_period_ms, feedback_s,
                            "encoder_msg_rate_ms, iq_msg_rate_ms and torques_msg_rate_ms")
        if len(beat_times) >= 2:
            self._refuse_period("heartbeat_period_ms", st.heartbeat_period_ms,
                                float(np.median(np.diff(beat_times))), "heartbeat_msg_rate_ms")
        if link.incomplete_sets > INCOMPLETE_FRACTION * len(stamps):
            raise ProfileError(
                f"[odrive] encoder_period_ms = {st.encoder_period_ms}: {link.where} sent "
                f"{link.incomplete_sets} feedback period(s) without each of encoder estimates, "
                "Iq and torques (set iq_msg_rate_ms and torques_msg_rate_ms to the encoder's)",
                source=st.source)

    def _refuse_period(self, key: str, declared_ms: int, measured_s: float,
                       setting: str) -> None:
        if abs(measured_s * 1e3 - declared_ms) > RATE_TOLERANCE * declared_ms:
            raise ProfileError(
                f"[odrive] {key} = {declared_ms}: {self.link.where} sends every "
                f"{measured_s * 1e3:.3g} ms (odrivetool: axis0.config.can.{setting} = "
                f"{declared_ms})", source=self.station.source)

    @property
    def info(self) -> DriveInfo:
        """What the drive is and can do (asked and measured at bring-up)."""
        return self._info

    # -- state -------------------------------------------------------------------------------
    def status(self) -> DriveStatus:
        """State (heartbeat), position and velocity (a fresh feedback set)."""
        return self.states.status()

    def enable(self, mode: Mode = Mode.VELOCITY) -> None:
        """Clear errors, select ``mode`` holding the axis, closed loop, confirmed.

        Raises
        ------
        DriveFaultError
            An axis error that does not clear or comes up.
        DriveStateError
            Closed loop not confirmed in time.
        """
        try:
            self.states.enable(mode)
        except DriveError:
            self.states.disable()
            raise

    def disable(self) -> None:
        """IDLE, confirmed by heartbeat (Estop when it cannot be); never raises."""
        self.states.disable()

    def quick_stop(self) -> None:
        """Brake to rest, then IDLE (Estop when unconfirmed); never raises."""
        self.states.quick_stop()

    def close(self) -> None:
        """IDLE, then release the bus."""
        try:
            self.disable()
        finally:
            self.link.close()

    # -- run ---------------------------------------------------------------------------------
    def run(self, excitation: Excitation) -> Recording:
        """Stream ``excitation`` at the feedback rate (or a whole fraction of it). See
        :meth:`Drive.run` and :mod:`hil.drives.odrive.acquire`.

        Raises
        ------
        DriveStateError
            Not enabled, or a sample rate the feedback rate does not divide; nothing moved.
        LimitViolationError
            The command leaves the unit's limits (nothing moved), or the measured motion left
            the monitor's envelope (the axis quick-stopped, then IDLE).
        DriveError
            An axis error, a lost link or heartbeat, too many lost rows: the axis IDLE, the
            partial recording attached.
        """
        states = self.states
        if states.state is not DriveState.ENABLED:
            raise DriveStateError(f"cannot run '{excitation.name}': drive is {states.state.value}")
        decimation(excitation, self.station.feedback_period_s)
        start = self.status()
        if start.state is not DriveState.ENABLED:
            states.make_safe(DriveStateError("not in closed loop"))
            raise DriveStateError(f"cannot run '{excitation.name}': {self.link.where} is not "
                                  f"in closed loop ({start.state.value})")
        check_limits(excitation, self.limits, start_position_rad=start.position_rad)
        self.link.stop_feeding()
        if excitation.mode is not states.mode:
            states.select(excitation.mode)
        run = StreamedRun()
        error: DriveError | None = None
        log.info("%s: streaming %s (%.2f s at %g Hz)", self.link.where, excitation.name,
                 excitation.duration_s, excitation.fs_hz)
        try:
            with collector_held():
                stream(excitation, states, run, MotionEnvelope.of(self.limits))
            states.hold(excitation.mode)
        except DriveError as exc:
            error = exc
        except KeyboardInterrupt as stop:  # a stop signal: quick stop, keep the rows so far
            states.quick_stop()
            raise interrupted(stop, to_recording(excitation, run, states, self._info)) from stop
        except BaseException:
            states.quick_stop()
            raise
        recording = to_recording(excitation, run, states, self._info)
        if error is None and not self.link.lockstep:
            error = late_commands(excitation, run, self.link.where, self.station.source)
        if error is not None:
            states.make_safe(error)
            error.partial_recording = recording
            raise error
        self.link.feed_while_idle()
        return recording
