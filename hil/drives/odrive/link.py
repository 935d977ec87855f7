"""The CAN link to one ODrive axis: python-can bus, CANSimple frames in and out, the
feedback sets a row is made of, the heartbeat watch and the drive's clock.

Frames are read directly (``bus.recv``) by whichever call waits for something, in the
order they arrived; nothing runs behind the caller's back except, while the axis is
enabled and idle on a station that declares the ODrive's watchdog, python-can's periodic
send of the hold command (its feed).

**The drive's clock.** In ``realtime`` pacing it is the frames' own time stamps (the
interface's, not the host's receipt: a host that paused does not see a silent drive); in
``lockstep`` (the emulator only) it is the number of feedback periods the host has
stepped, so the host's pauses, when nothing moves, are no time at all.

**Heartbeat watch.** Every processed frame moves the drive's clock; a heartbeat more than
``heartbeat_timeout_s`` of it old is a :class:`DriveCommunicationError` (an ODrive that
keeps sending its feedback but stopped its heartbeat, e.g. a firmware gone astray, is
not trusted); no frame at all for ``frame_timeout_s`` of the wall clock is one too.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import can

from hil.drives.odrive.protocol import (
    Cmd,
    Heartbeat,
    arbitration_id,
    decode_float_pair,
    decode_heartbeat,
    decode_u32_pair,
    split_id,
)
from hil.drives.odrive.station import OdriveStation
from hil.errors import DriveCommunicationError

log = logging.getLogger(__name__)

FEEDBACK_CMDS = (Cmd.GET_ENCODER_ESTIMATES, Cmd.GET_IQ, Cmd.GET_TORQUES)
LOCKSTEP_WAIT_S = 0.01  # for a stepped period's set before asking whether it is complete


@dataclass(frozen=True, slots=True)
class Feedback:
    """One feedback period's messages, in ODrive units (turns, turns/s, A, N·m), and the
    encoder message's time stamp."""

    stamp_s: float
    position_turns: float
    velocity_turns_s: float
    iq_setpoint_a: float
    iq_measured_a: float
    torque_target_nm: float
    torque_estimate_nm: float


class OdriveLink:
    """CANSimple to one node.

    Parameters
    ----------
    station : OdriveStation
        Interface, channel, bitrate, node id, periods, timeouts, pacing.

    Raises
    ------
    DriveCommunicationError
        The bus cannot be opened, a frame cannot be sent, or the drive went silent.
    """

    def __init__(self, station: OdriveStation) -> None:
        self.station = station
        self.node_id = station.node_id
        self.lockstep = station.pacing == "lockstep"
        self._bus: Any = None
        self._pending: dict[int, tuple[float, float, float]] = {}
        self._sets: deque[Feedback] = deque()
        self.heartbeat: Heartbeat | None = None
        self.heartbeats = 0  # heartbeats processed since the link opened
        self.heartbeat_at_s: float | None = None  # on the drive's clock
        self.errors: tuple[int, int] | None = None  # Get_Error: active, disarm reason
        self.latest: Feedback | None = None
        self.incomplete_sets = 0  # a feedback message repeated before its set completed
        self.ticks = 0  # lockstep: feedback periods stepped
        self._drive_time_s = 0.0
        self._last_command: tuple[int, bytes] = (Cmd.SET_INPUT_VEL, bytes(8))
        self._feed: Any = None  # python-can's periodic send of the hold command

    # -- life cycle ------------------------------------------------------------------------
    @property
    def where(self) -> str:
        return self.station.where

    def open(self) -> None:
        """Open the bus, filtered to this node's frames."""
        st = self.station
        try:
            self._bus = can.Bus(interface=st.interface, channel=st.channel, bitrate=st.bitrate,
                                **dict(st.can_options))
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            raise DriveCommunicationError(f"{self.where}: cannot open the bus: {exc}") from exc
        self._bus.set_filters([{"can_id": self.node_id << 5, "can_mask": 0x7E0,
                                "extended": False}])

    def close(self) -> None:
        self.stop_feeding()
        if self._bus is not None:
            try:
                self._bus.shutdown()
            finally:
                self._bus = None

    # -- sending ---------------------------------------------------------------------------
    def send(self, cmd: int, data: bytes = b"", *, remote: bool = False) -> None:
        """One frame to the node (a remote frame asks for ``cmd``'s message)."""
        if self._bus is None:
            raise DriveCommunicationError(f"{self.where}: the bus is closed")
        message = can.Message(arbitration_id=arbitration_id(self.node_id, cmd), data=data,
                              is_extended_id=False, is_remote_frame=remote,
                              dlc=8 if remote else len(data))
        try:
            self._bus.send(message, timeout=self.station.frame_timeout_s)
        except can.CanError as exc:
            raise DriveCommunicationError(f"{self.where}: cannot send {Cmd(cmd).name}: "
                                          f"{exc}") from exc

    def command(self, cmd: int, data: bytes) -> None:
        """Send a setpoint (Set_Input_*): remembered as the hold :meth:`step` repeats."""
        self._last_command = (cmd, data)
        self._setpoint(cmd, data)

    def step(self) -> None:
        """Repeat the last setpoint (in lockstep: one feedback period of the emulator)."""
        self._setpoint(*self._last_command)

    def _setpoint(self, cmd: int, data: bytes) -> None:
        """In lockstep a setpoint steps one period of the emulator, whose set is awaited
        here: it is then the only one :meth:`lockstep_feedback` can take, and ``latest``,
        however slowly the emulator ran (a set left untaken by a hold would otherwise be
        taken for the next period's, or not, as the threads happened to run)."""
        if self.lockstep:
            self._sets.clear()
        self.send(cmd, data)
        if self.lockstep:
            self._await_lockstep_set()

    def feed_while_idle(self) -> None:
        """On a station declaring the ODrive's watchdog (realtime): repeat the hold command
        every quarter of it until :meth:`stop_feeding` (python-can's periodic send)."""
        timeout = self.station.watchdog_timeout_s
        if self.lockstep or not timeout or self._bus is None:
            return
        self.stop_feeding()
        cmd, data = self._last_command
        message = can.Message(arbitration_id=arbitration_id(self.node_id, cmd), data=data,
                              is_extended_id=False)
        self._feed = self._bus.send_periodic(message, timeout / 4)

    def stop_feeding(self) -> None:
        if self._feed is not None:
            self._feed.stop()
            self._feed = None

    # -- receiving -------------------------------------------------------------------------
    def drive_time_s(self) -> float:
        """The drive's clock (module docstring)."""
        if self.lockstep:
            return self.ticks * self.station.feedback_period_s
        return self._drive_time_s

    def _receive(self, timeout_s: float) -> can.Message | None:
        try:
            message: can.Message | None = self._bus.recv(timeout_s)
        except can.CanError as exc:
            raise DriveCommunicationError(f"{self.where}: bus error: {exc}") from exc
        return message

    def pump(self, timeout_s: float) -> int | None:
        """Process one frame (waiting up to ``timeout_s``); its command id, None on none."""
        if self._bus is None:
            raise DriveCommunicationError(f"{self.where}: the bus is closed")
        return self._process(self._receive(timeout_s))

    def _process(self, message: can.Message | None) -> int | None:
        if message is None or message.is_remote_frame or message.is_error_frame:
            return None
        node, cmd = split_id(message.arbitration_id)
        if node != self.node_id:
            return None
        data = bytes(message.data)
        if not self.lockstep:
            self._drive_time_s = max(self._drive_time_s, float(message.timestamp))
        if cmd == Cmd.HEARTBEAT:
            self.heartbeat = decode_heartbeat(data)
            self.heartbeats += 1
            self.heartbeat_at_s = self.drive_time_s()
        elif cmd == Cmd.GET_ERROR:
            self.errors = decode_u32_pair(data)
        elif cmd in FEEDBACK_CMDS:
            self._feedback(cmd, data, float(message.timestamp))
        self.check_heartbeat()
        return cmd

    def _feedback(self, cmd: int, data: bytes, stamp_s: float) -> None:
        if cmd in self._pending:  # a message of this set again: the set was incomplete
            self.incomplete_sets += 1
            self._pending.clear()
        first, second = decode_float_pair(data)
        self._pending[cmd] = (first, second, stamp_s)
        if len(self._pending) < len(FEEDBACK_CMDS):
            return
        pos, vel, stamp = self._pending[Cmd.GET_ENCODER_ESTIMATES]
        iq_set, iq_meas, _ = self._pending[Cmd.GET_IQ]
        target, estimate, _ = self._pending[Cmd.GET_TORQUES]
        self._pending.clear()
        feedback = Feedback(stamp, pos, vel, iq_set, iq_meas, target, estimate)
        self.latest = feedback
        self._sets.append(feedback)
        if self.lockstep:
            self.ticks += 1

    def check_heartbeat(self) -> None:
        """Raise when the last heartbeat is older than ``heartbeat_timeout_s`` of the
        drive's clock (module docstring)."""
        if self.heartbeat_at_s is None:
            return
        silent = self.drive_time_s() - self.heartbeat_at_s
        if silent > self.station.heartbeat_timeout_s:
            raise DriveCommunicationError(
                f"{self.where}: no heartbeat for {silent:.3f} s of the drive's clock while its "
                f"feedback kept coming (heartbeat_timeout_s = "
                f"{self.station.heartbeat_timeout_s:g} s in {self.station.source})")

    def next_feedback(self, timeout_s: float | None = None) -> Feedback | None:
        """The oldest feedback set not yet taken, waiting up to ``timeout_s`` (default the
        station's ``frame_timeout_s``) of the wall clock; None when none came."""
        wait = self.station.frame_timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + wait
        while not self._sets:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            self.pump(left)
        return self._sets.popleft()

    def backlog(self) -> int:
        """Feedback sets received and not yet taken."""
        return len(self._sets)

    def drain(self) -> None:
        """Process every frame already received; the feedback sets are dropped (a fresh
        wait then returns the drive's next period)."""
        while self.pump(0.0) is not None:
            pass
        self._sets.clear()

    def request(self, cmd: int, timeout_s: float | None = None) -> bytes:
        """Ask for ``cmd``'s message by a remote frame and return its payload; frames that
        arrive before it are processed as usual.

        Raises
        ------
        DriveCommunicationError
            No answer within ``timeout_s`` (default ``frame_timeout_s``).
        """
        wait = self.station.frame_timeout_s if timeout_s is None else timeout_s
        self.send(cmd, remote=True)
        deadline = time.monotonic() + wait
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise DriveCommunicationError(
                    f"{self.where}: no answer to {Cmd(cmd).name} within {wait:g} s (is the "
                    f"node id {self.node_id} and bitrate {self.station.bitrate} right?)")
            message = self._receive(left)
            if message is None or message.is_remote_frame or message.is_error_frame:
                continue
            node, got = split_id(message.arbitration_id)
            if node != self.node_id:
                continue
            if got == cmd:
                return bytes(message.data)
            self._process(message)

    def lockstep_feedback(self) -> Feedback | None:
        """Lockstep: the set of the period the last setpoint stepped, or None when it was
        lost (or already taken)."""
        return self._sets.popleft() if self._sets else None

    def _await_lockstep_set(self) -> None:
        """Wait briefly for the set of the period just stepped, then settle
        (:meth:`settle_lockstep`): a late set is still taken for its own period, a lost one
        costs one round trip, not ``frame_timeout_s``."""
        deadline = time.monotonic() + min(LOCKSTEP_WAIT_S, self.station.frame_timeout_s)
        while not self._sets:
            left = deadline - time.monotonic()
            if left <= 0:
                self.settle_lockstep()
                return
            self.pump(left)

    def settle_lockstep(self) -> None:
        """After a feedback set did not come in lockstep: ask the node for its version and
        wait for the answer. The emulator answers in order, so every frame of the period
        it owed is in by then (a late one is not taken for the next period's); a set still
        incomplete is dropped."""
        self.request(Cmd.GET_VERSION)
        if self._pending:
            self.incomplete_sets += 1
            self._pending.clear()
