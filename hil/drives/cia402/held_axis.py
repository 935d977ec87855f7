"""A gimbal's other axis on the same CAN bus: moved between the runs of the axis under
test and holding its angle during them, by its own drive.

The held node runs CiA 402 profile position (mode 1): its own position loop and motion
profile (0x6081 speed, 0x6083/0x6084 acceleration, 0x6067 window); the host sends it
nothing cyclic (its PDOs are switched off: the bus carries the axis under test's stream and
the held nodes' heartbeats, :func:`bus_load`), commands a move by SDO (0x607A, then a new
set-point on controlword bit 4, acknowledged on statusword bit 12) and waits for "target
reached" (bit 10) while the link keeps producing the one SYNC stream. A host that dies
stops it like the axis under test (consumer heartbeat 0x1016, 0x6007 quick stop).
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any

import canopen
import numpy as np

from hil.drives.cia402.acquire import RECORDER_SAMPLE
from hil.drives.cia402.link import CanLink, sdo_read, sdo_write, sdo_write_standard
from hil.drives.cia402.protocol import (
    CW_DISABLE_VOLTAGE,
    CW_ENABLE_OPERATION,
    CW_SHUTDOWN,
    CW_SWITCH_ON,
    SW_FAULT,
    cycle_bits,
    frame_bits,
    state_of,
)
from hil.drives.station import CanOpenStation
from hil.errors import DriveFaultError, DriveStateError, LimitViolationError

log = logging.getLogger(__name__)

PROFILE_POSITION = 1  # 0x6060
CW_NEW_SETPOINT = 0x0010 | 0x0020  # bit 4 new set-point, bit 5 change immediately
SW_TARGET_REACHED = 0x0400
SW_SETPOINT_ACKNOWLEDGE = 0x1000
RECORDER_DONE = 2  # the recorder's state (its sub 2): finished
STATUS_POLL_S = 0.01  # SYNC periods between two statusword reads while a held axis moves


def bus_load(station: CanOpenStation, *, rpdo_bytes: int, tpdo_bytes: tuple[int, ...]) -> float:
    """Fraction of the bus the SYNC stream of the axis under test and every node's
    heartbeat take (the host's too; SDO traffic between runs is not counted)."""
    per_s = cycle_bits(rpdo_bytes, tpdo_bytes) / station.sync_period_s
    heartbeats = 2 + len(station.held)  # the host, the axis under test, each held axis
    per_s += heartbeats * frame_bits(1) / station.heartbeat_period_s
    return per_s / station.bitrate


class HeldAxis:
    """One held axis (``name``, node ``node_id``) on ``link``'s network.

    Raises (at construction)
    ------------------------
    DriveStateError
        The node lacks profile position mode, or refused a setting.
    DriveCommunicationError
        The node does not answer.
    """

    def __init__(self, link: CanLink, *, name: str, node_id: int) -> None:
        self.link, self.name, self.node_id = link, name, node_id
        self.station = link.station
        node = canopen.RemoteNode(node_id, str(self.station.eds_path))
        node.sdo.RESPONSE_TIMEOUT = self.station.sdo_timeout_s
        link.network.add_node(node)
        self.node = node
        self.enabled = False
        self.counts_per_rad = 1.0
        self._bring_up()

    def read(self, index: int, subindex: int = 0) -> Any:
        return sdo_read(self.node, index, subindex)

    def write(self, index: int, subindex: int, value: Any) -> None:
        sdo_write(self.node, index, subindex, value)

    def _bring_up(self) -> None:
        st, hold = self.station, self.station.gimbal.hold
        self.node.nmt.state = "PRE-OPERATIONAL"
        self.write(0x1017, 0, round(st.heartbeat_period_s * 1e3))
        if not int(self.read(0x6502)) & 0x01:
            raise DriveStateError(f"node {self.node_id} ({self.name} axis) has no profile "
                                  "position mode (0x6502 bit 0): it cannot hold its angle")
        counts = int(self.read(0x608F, 1)) // max(1, int(self.read(0x608F, 2)))
        self.counts_per_rad = counts / (2 * math.pi)
        for n in range(4):  # nothing cyclic from or to a held axis
            for comm in (0x1400 + n, 0x1800 + n):
                if comm in self.node.object_dictionary:
                    self.write(comm, 1, int(self.read(comm, 1)) | 0x80000000)
        sdo_write_standard(self.node, 0x1016, 1, "I",
                           st.host_node_id << 16 | round(st.host_heartbeat_timeout_s * 1e3))
        sdo_write_standard(self.node, 0x6007, 0, "h", st.abort_connection_option_code)
        self.write(0x6060, 0, PROFILE_POSITION)
        self.write(0x6081, 0, self._counts(hold.speed_rad_s))
        self.write(0x6083, 0, self._counts(hold.accel_rad_s2))
        self.write(0x6084, 0, self._counts(hold.accel_rad_s2))
        self.write(0x6067, 0, max(1, self._counts(hold.window_rad)))
        self.node.nmt.state = "OPERATIONAL"

    @property
    def address(self) -> str:
        return f"node {self.node_id}"

    def _counts(self, value_rad: float) -> int:
        return round(value_rad * self.counts_per_rad)

    @property
    def position_rad(self) -> float:
        return int(self.read(0x6064)) / self.counts_per_rad

    def _statusword(self) -> int:
        word = int(self.read(0x6041))
        if word & SW_FAULT:
            raise DriveFaultError(f"node {self.node_id} ({self.name} axis) faulted",
                                  code=int(self.read(0x603F)))
        return word

    def _until(self, what: str, done: Any, timeout_s: float) -> int:
        """Keep the SYNC stream going until ``done(statusword)``; the statusword."""
        deadline = time.monotonic() + timeout_s
        per_read = max(1, round(STATUS_POLL_S / self.station.sync_period_s))
        while True:
            for _ in range(per_read):
                self.link.tick()
            word = self._statusword()
            if done(word):
                return word
            if time.monotonic() > deadline:
                raise DriveStateError(f"node {self.node_id} ({self.name} axis): {what} not "
                                      f"confirmed within {timeout_s:g} s (statusword "
                                      f"0x{word:04X}, {state_of(word)})")

    def enable(self) -> None:
        """Shutdown, switch on, enable operation: it holds where it stands."""
        timeout_s = self.station.state_timeout_s
        for word, target in ((CW_SHUTDOWN, "READY TO SWITCH ON"), (CW_SWITCH_ON, "SWITCHED ON"),
                             (CW_ENABLE_OPERATION, "OPERATION ENABLED")):
            self.write(0x6040, 0, word)
            self._until(target, lambda sw, t=target: state_of(sw) in (t, "OPERATION ENABLED"),
                        timeout_s)
        self.enabled = True

    def move_to(self, angle_rad: float) -> None:
        """Move to ``angle_rad`` and hold it (reached within the window, then settled)."""
        if not self.enabled:
            self.enable()
        hold = self.station.gimbal.hold
        distance = abs(angle_rad - self.position_rad)
        self.write(0x607A, 0, self._counts(angle_rad))
        self.write(0x6040, 0, CW_ENABLE_OPERATION | CW_NEW_SETPOINT)
        self._until("new set-point acknowledged", lambda sw: sw & SW_SETPOINT_ACKNOWLEDGE,
                    self.station.state_timeout_s)
        self.write(0x6040, 0, CW_ENABLE_OPERATION)
        move_s = distance / hold.speed_rad_s + hold.speed_rad_s / hold.accel_rad_s2
        self._until(f"target {angle_rad:+.4f} rad reached",
                    lambda sw: sw & SW_TARGET_REACHED and not sw & SW_SETPOINT_ACKNOWLEDGE,
                    move_s + hold.timeout_s)
        settled = time.monotonic() + hold.settle_s
        if self.station.sync_pacing == "lockstep":  # the SYNC is the clock: count periods
            for _ in range(round(hold.settle_s / self.station.sync_period_s)):
                self.link.tick()
        else:
            while time.monotonic() < settled:
                self.link.tick()
        log.info("node %d (%s axis) holds %+.4f rad", self.node_id, self.name, angle_rad)

    @property
    def can_play(self) -> bool:
        """It has the drive recorder and waveform table of the station's object map (the
        held node is the drive model the map describes)."""
        return self.station.object_map.has_recorder

    def play(self, path_rad: np.ndarray, *, divider: int) -> None:
        """Follow ``path_rad`` from its waveform table (one sample per ``divider`` control
        periods, in profile position: its position loop follows the table) and record
        itself alongside: both start at the next SYNC, as does whatever else the host
        starts before it (the axis under test's own table).

        Raises
        ------
        LimitViolationError
            The path leaves the node's software position limits (0x607D); nothing moved.
        DriveStateError
            The node refused the table (too long for its recorder, not enabled).
        """
        om = self.station.object_map
        assert om.recorder_index is not None
        assert om.waveform_index is not None
        low, high = (int(self.read(0x607D, sub)) / self.counts_per_rad for sub in (1, 2))
        if not low <= float(np.min(path_rad)) <= float(np.max(path_rad)) <= high:
            raise LimitViolationError(
                f"node {self.node_id} ({self.name} axis): the path spans "
                f"[{np.min(path_rad):+.4f}, {np.max(path_rad):+.4f}] rad, outside its drive's "
                f"software position limits (0x607D) [{low:+.4f}, {high:+.4f}] rad")
        if not self.enabled:
            self.enable()
        counts = np.round(np.repeat(np.asarray(path_rad, dtype=np.float64), divider)
                          * self.counts_per_rad).astype("<i4")
        self.write(om.waveform_index, 1, counts.tobytes())
        self.write(om.recorder_index, 3, divider)
        self.write(om.recorder_index, 1, 1)

    def played_rad(self) -> np.ndarray:
        """Where the node's recorder saw it at each sample of the path it played (rad).

        Raises
        ------
        DriveStateError
            Its recorder did not finish the path (stopped, or still running).
        """
        om = self.station.object_map
        assert om.recorder_index is not None
        if int(self.read(om.recorder_index, 2)) != RECORDER_DONE:
            raise DriveStateError(f"node {self.node_id} ({self.name} axis): its drive "
                                  "recorder did not finish the path")
        data = bytes(self.read(om.recorder_index, 7))
        row = RECORDER_SAMPLE.itemsize
        samples = np.frombuffer(data[: len(data) // row * row], dtype=RECORDER_SAMPLE)
        return np.asarray(samples["pos"] / self.counts_per_rad, dtype=np.float64)

    def disable(self) -> None:
        """Disable voltage (best effort: the link may be gone)."""
        self.enabled = False
        try:
            self.write(0x6040, 0, CW_DISABLE_VOLTAGE)
            sdo_write_standard(self.node, 0x1016, 1, "I", 0)  # a clean end is no lost host
            self.node.nmt.state = "PRE-OPERATIONAL"
        except Exception as exc:
            log.warning("node %d (%s axis): disabling reported %s", self.node_id, self.name,
                        exc)
