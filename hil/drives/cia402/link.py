"""The CANopen link to one CiA 402 node: NMT, SDO, our PDO layout, SYNC ticks, monitoring.

We are the SYNC producer. Every exchange with the drive's cyclic side is a *tick*: send
the RPDO (controlword + target), send SYNC, collect the TPDOs that SYNC triggers. With
``sync_pacing = "realtime"`` ticks follow the wall clock (the RPDO half a period before
its SYNC, so it cannot lose arbitration to the SYNC); with ``"lockstep"`` the next tick
starts as soon as the previous one was answered.

canopen 2.4 traps avoided here (each has a test in ``tests/drives/test_canopen_traps.py``):
``BaseNode402.setup_pdos`` asserts on an NMT state it only knows from a heartbeat, so we
wait for the heartbeat and configure PDOs ourselves; a synchronous RPDO is only sent by
``PdoMap.start()``, so we transmit it explicitly on every tick; ``check_statusword``
treats any TPDO received twice as periodic, so we key feedback to our own SYNC count; and
a python-can Notifier that died on a bus error is only visible through ``network.check()``,
which every tick calls.
"""

from __future__ import annotations

import logging
import struct
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import can
import canopen
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

from hil.drives.cia402.protocol import (
    RPDO_FORMAT,
    RPDO_LAYOUT,
    SW_FAULT,
    TPDO1_FORMAT,
    TPDO2_FORMAT,
    TPDO_LAYOUT,
    TpdoLayout,
    state_of,
)
from hil.drives.station import CanOpenStation
from hil.errors import DriveCommunicationError, DriveError, DriveFaultError, DriveStateError
from hil.motion import Mode

log = logging.getLogger(__name__)

_TPDO1 = struct.Struct(TPDO1_FORMAT)
_TPDO2 = struct.Struct(TPDO2_FORMAT)
SYNC_GENERATE = 0x40000000  # CiA 301 0x1005 bit 30: the node generates the SYNC
_UPLOAD_STATUSWORD = bytes((0x40, 0x41, 0x60, 0x00, 0, 0, 0, 0))  # SDO initiate upload 0x6041:00
NMT_NAMES = {0: "INITIALISING", 4: "STOPPED", 5: "OPERATIONAL", 127: "PRE-OPERATIONAL"}


class CanLink:
    """Owns the python-can bus, the canopen network and the node's cyclic exchange.

    Parameters
    ----------
    station : CanOpenStation
        Interface, channel, bitrate, node, EDS and the link's timing (SYNC period and
        pacing, PDO, SDO and heartbeat timeouts).

    Attributes
    ----------
    sync_index : int
        The index of the last SYNC sent; feedback is keyed by it (``rx1``, ``rx2``).
    emcy : list of (int, float)
        EMCY codes received (with their host time), newest last.
    mode, controlword, target
        What the RPDO of a tick without arguments carries.
    """

    def __init__(self, station: CanOpenStation) -> None:
        self.station = station
        self.node_id = station.node_id
        self.network = canopen.Network()
        self.node: canopen.RemoteNode | None = None
        self.sync_index = -1  # index of the last SYNC we sent
        self.sync_period_s = station.sync_period_s  # the drive's 0x1006, as last written
        self.sync_sent_s: list[float] = []  # monotonic time of each SYNC since forget()
        # lockstep: called once per answered SYNC (a bench instrument read in step with it)
        self.in_step: Callable[[], None] | None = None
        self.rx1: dict[int, bytes] = {}
        self.rx2: dict[int, bytes] = {}
        self.emcy: list[tuple[int, float]] = []
        self.heartbeat_state: int | None = None
        self.heartbeat_time = 0.0
        self.mode = Mode.VELOCITY
        self.controlword = 0
        self.target = 0
        self._answered = threading.Event()
        self._heartbeat_seen = threading.Event()
        self._host_heartbeat: Any = None  # our own heartbeat (a periodic task)
        self._next_deadline = 0.0
        # a SYNC producer other than this loop: the SYNCs are counted as they are seen
        self._observed = station.sync_producer != "host"
        self._sync_task: Any = None  # python-can's periodic SYNC, and its period
        self._sync_task_period_s = 0.0
        self._progress = threading.Event()  # a SYNC or a TPDO seen (observed SYNCs)
        self._aligned = False  # a streamed run: each tick's RPDO must meet the next SYNC
        self._connected = False
        self._direct = False
        self.network.NOTIFIER_CYCLE = 0.05  # so the receive thread stops promptly

    # -- connection ------------------------------------------------------------------
    def open(self) -> None:
        """Connect to the bus and listen to the node's heartbeat, EMCY and TPDOs.

        Raises
        ------
        DriveCommunicationError
            The CAN interface cannot be opened.
        """
        st = self.station
        options = dict(st.can_options)
        if self._observed:  # the host counts the periodic task's SYNCs as they go out
            options.setdefault("receive_own_messages", True)
        try:
            self.network.connect(
                interface=st.interface, channel=st.channel, bitrate=st.bitrate, **options
            )
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            raise DriveCommunicationError(
                f"cannot open CAN interface '{st.interface}' channel '{st.channel}': {exc}"
            ) from exc
        self._connected = True
        node = canopen.RemoteNode(self.node_id, str(st.eds_path))
        node.sdo.RESPONSE_TIMEOUT = st.sdo_timeout_s
        self.network.add_node(node)
        self.node = node
        node.emcy.add_callback(self._on_emcy)
        base = self.node_id
        self.network.subscribe(0x700 + base, self._on_heartbeat)
        self.network.subscribe(0x180 + base, self._on_tpdo1)
        self.network.subscribe(0x280 + base, self._on_tpdo2)
        if self._observed:
            self.network.subscribe(0x80, self._on_sync)

    def start_host_heartbeat(self) -> None:
        """Produce the host's heartbeat (node ``host_node_id``, state OPERATIONAL, every
        ``heartbeat_period_s``): the drive's consumer (0x1016) stops the axis when it ends."""
        if self._host_heartbeat is None:
            st = self.station
            self._host_heartbeat = self.network.send_periodic(
                0x700 + st.host_node_id, bytes([0x05]), st.heartbeat_period_s
            )

    def stop_host_heartbeat(self) -> None:
        """End the host's heartbeat (the drive's consumer then reacts after its time)."""
        task, self._host_heartbeat = self._host_heartbeat, None
        if task is not None:
            try:
                task.stop()
            except Exception as exc:  # the bus may be gone already
                log.warning("stopping the host heartbeat reported %r", exc)

    def close(self) -> None:
        """Disconnect from the bus (a receive thread that died is logged, not raised)."""
        self.stop_host_heartbeat()
        self._stop_sync_task()
        if self._connected:
            self._connected = False
            try:
                self.network.disconnect()
            except Exception as exc:  # the receive thread may already have died
                log.warning("CAN disconnect reported %r", exc)

    @property
    def connected(self) -> bool:
        """Whether the bus is open (it may still have failed since: see :meth:`check`)."""
        return self._connected

    # -- listeners (python-can Notifier thread) -----------------------------------------
    def _on_heartbeat(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if data:
            self.heartbeat_state = data[0] & 0x7F
            self.heartbeat_time = time.monotonic()
            self._heartbeat_seen.set()

    def _on_emcy(self, entry: Any) -> None:
        if entry.code & 0xFF00:
            self.emcy.append((int(entry.code), time.monotonic()))
            log.warning("node %d EMCY 0x%04X (%s)", self.node_id, entry.code, entry.get_desc())

    def _on_tpdo1(self, can_id: int, data: bytearray, timestamp: float) -> None:
        index = self.sync_index
        self.rx1[index] = bytes(data)
        if index in self.rx2:
            self._answered.set()
        self._progress.set()

    def _on_tpdo2(self, can_id: int, data: bytearray, timestamp: float) -> None:
        index = self.sync_index
        self.rx2[index] = bytes(data)
        if index in self.rx1:
            self._answered.set()
        self._progress.set()

    def _on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        """A SYNC of the periodic producer, seen: the TPDOs after it are its answer (frames
        arrive in order, so this index moves before they are filed)."""
        self.sync_index += 1
        self.sync_sent_s.append(timestamp)  # the interface's time of the frame
        self._progress.set()

    def _start_sync_task(self) -> None:
        """The SYNC producer started: python-can's periodic SYNC at the present period
        (restarted when it changed), or the drive told to produce it (0x1005 bit 30; its
        period is the 0x1006 the drive was given)."""
        if self.station.sync_producer == "node":
            if self._sync_task is None:
                self.write_standard(0x1005, 0, "I", SYNC_GENERATE | 0x80)
                self._sync_task = "node"
            return
        if self._sync_task is not None and self._sync_task_period_s == self.sync_period_s:
            return
        self._stop_sync_task()
        self._sync_task = self.network.send_periodic(0x80, b"", self.sync_period_s)
        self._sync_task_period_s = self.sync_period_s

    def _stop_sync_task(self) -> None:
        task, self._sync_task = self._sync_task, None
        if task == "node":
            try:
                self.write_standard(0x1005, 0, "I", 0x80)
            except DriveError as exc:  # closing: the node may be gone
                log.warning("node %d: SYNC production not stopped: %s", self.node_id, exc)
        elif task is not None:
            task.stop()

    # -- health ----------------------------------------------------------------------
    def check(self) -> None:
        """Raise if the receive thread died (bus error) or the heartbeat stopped."""
        try:
            self.network.check()
        except Exception as exc:
            raise DriveCommunicationError(
                f"CAN receive thread stopped on node {self.node_id}'s bus: {exc}"
            ) from exc
        age = time.monotonic() - self.heartbeat_time
        if self.heartbeat_state is not None and age > self.station.heartbeat_timeout_s:
            raise DriveCommunicationError(f"no heartbeat from node {self.node_id} for {age:.2f} s")

    def restart_receiver(self) -> bool:
        """After a bus error: start a new Notifier so the drive's state can be verified."""
        bus = self.network.bus
        if bus is None:
            return False
        try:
            if self.network.notifier is not None:
                self.network.notifier.stop(0.5)
            self.network.notifier = can.Notifier(bus, self.network.listeners, 0.05)
        except Exception as exc:  # the bus itself may be gone
            log.warning("could not restart the CAN receiver: %r", exc)
            return False
        return True

    # -- SDO -------------------------------------------------------------------------
    def read(self, index: int, subindex: int = 0) -> Any:
        """An object's value by SDO upload (:func:`sdo_read`)."""
        assert self.node is not None
        return sdo_read(self.node, index, subindex)

    def upload(self, index: int, subindex: int) -> bytes:
        """An object's bytes by SDO upload, by its address (whether or not the EDS has it)."""
        assert self.node is not None
        sdo = self.node.sdo
        return bytes(sdo_access(self.node, lambda _: sdo.upload(index, subindex), index,
                                subindex, raw=True))

    def write(self, index: int, subindex: int, value: Any) -> None:
        """An object's value by SDO download (:func:`sdo_write`)."""
        assert self.node is not None
        sdo_write(self.node, index, subindex, value)

    def write_standard(self, index: int, subindex: int, code: str, value: int) -> None:
        """A standard object the EDS may not declare (:func:`sdo_write_standard`)."""
        assert self.node is not None
        sdo_write_standard(self.node, index, subindex, code, value)

    # -- NMT -------------------------------------------------------------------------
    def command_nmt(self, state: str) -> None:
        """Command an NMT state, unconfirmed (the node may not produce a heartbeat yet)."""
        assert self.node is not None
        self.node.nmt.state = state

    def nmt(self, state: str, *, timeout_s: float | None = None) -> None:
        """Command an NMT state and confirm it from the node's heartbeat."""
        expected = {"PRE-OPERATIONAL": 127, "OPERATIONAL": 5, "STOPPED": 4}[state]
        self._heartbeat_seen.clear()
        self.command_nmt(state)
        deadline = time.monotonic() + (timeout_s or self.station.heartbeat_timeout_s * 2)
        while time.monotonic() < deadline:
            self._heartbeat_seen.wait(0.05)
            self._heartbeat_seen.clear()
            if self.heartbeat_state == expected:
                return
        seen = NMT_NAMES.get(self.heartbeat_state or -1, str(self.heartbeat_state))
        raise DriveCommunicationError(
            f"node {self.node_id} did not confirm NMT {state} by heartbeat (last seen: {seen})"
        )

    def configure_pdos(self, tpdos: TpdoLayout = TPDO_LAYOUT) -> None:
        """Write our PDO layout (node must be PRE-OPERATIONAL; confirmed by the caller);
        ``tpdos``: :data:`TPDO_LAYOUT`, or :func:`tpdo_layout_mean` (torque averaged)."""
        base = self.node_id
        for n, entries in [(*RPDO_LAYOUT[m],) for m in (Mode.VELOCITY, Mode.TORQUE, Mode.POSITION)]:
            self._map(0x1400 + n - 1, 0x1600 + n - 1, 0x200 + 0x100 * (n - 1) + base, entries)
        for n, entries in tpdos:
            self._map(0x1800 + n - 1, 0x1A00 + n - 1, 0x180 + 0x100 * (n - 1) + base, entries)
        for n in range(len(tpdos) + 1, 5):  # the drive's other TPDOs: off
            if 0x1800 + n - 1 in self.node.object_dictionary:  # type: ignore[union-attr]
                cob = self.read(0x1800 + n - 1, 1)
                self.write(0x1800 + n - 1, 1, cob | 0x80000000)

    def _map(self, comm: int, mapping: int, cob: int,
             entries: tuple[tuple[int, int, int], ...]) -> None:
        self.write(comm, 1, cob | 0x80000000)  # invalidate while remapping
        self.write(comm, 2, 1)  # synchronous, every SYNC
        self.write(mapping, 0, 0)
        for sub, (index, subindex, bits) in enumerate(entries, start=1):
            self.write(mapping, sub, index << 16 | subindex << 8 | bits)
        self.write(mapping, 0, len(entries))
        self.write(comm, 1, cob)

    # -- the cyclic exchange ------------------------------------------------------------
    def rpdo_payload(self, mode: Mode, controlword: int, target: int,
                     torque_offset: int = 0) -> tuple[int, bytes]:
        """COB-ID and data of the RPDO carrying ``controlword`` and the target of ``mode``
        (and, in velocity mode, the torque offset in per-mille of the rated torque)."""
        n = RPDO_LAYOUT[mode][0]
        values = (controlword, target, torque_offset) if mode is Mode.VELOCITY else (
            controlword, target)
        return 0x200 + 0x100 * (n - 1) + self.node_id, struct.pack(RPDO_FORMAT[mode], *values)

    def tick(self, cob: int | None = None, payload: bytes | None = None) -> bool:
        """One cycle: RPDO, SYNC, feedback. Returns whether both TPDOs of it arrived.

        Without ``cob``/``payload`` the held controlword and target are sent.
        """
        if cob is None or payload is None:
            cob, payload = self.rpdo_payload(self.mode, self.controlword, self.target)
        if self._observed:
            return self._observed_tick(cob, payload)
        period = self.sync_period_s
        realtime = self.station.sync_pacing == "realtime"
        try:
            self.network.send_message(cob, payload)
            if realtime:
                self._wait(self._next_deadline, until_answered=False)
            self._answered.clear()
            self.sync_index += 1
            self.network.send_message(0x80, b"")
            self.sync_sent_s.append(time.monotonic())
            if realtime:
                now = time.monotonic()
                if self._next_deadline < now - period:
                    self._next_deadline = now  # we fell behind: resynchronise
                self._next_deadline += period
                self._wait(self._next_deadline - period / 2, until_answered=False)
                return self.sync_index in self.rx1 and self.sync_index in self.rx2
            answered = self._wait(time.monotonic() + self.station.pdo_timeout_s,
                                  until_answered=True)
            if not answered:
                # lockstep: a drive (an emulator on a loaded host) answering later than the
                # PDO timeout would have its TPDOs filed under the next SYNC, every row after
                # it one SYNC late; it answers an SDO request after this SYNC's TPDOs, so
                # the round trip collects them under this SYNC first (or proves them lost)
                self._barrier()
                answered = self.sync_index in self.rx1 and self.sync_index in self.rx2
            if self.in_step is not None:  # lockstep: what is read once per SYNC, in step
                self.in_step()
            return answered
        except can.CanError as exc:
            raise DriveCommunicationError(f"CAN error on node {self.node_id}'s bus: {exc}") from exc
        except DriveCommunicationError:
            raise
        except Exception as exc:  # network.check() re-raises what killed the receiver
            raise DriveCommunicationError(f"CAN receive thread stopped: {exc}") from exc

    def _observed_tick(self, cob: int, payload: bytes) -> bool:
        """One cycle under a SYNC producer other than this loop: the RPDO, then the next
        SYNC seen, then its TPDOs awaited up to half a period.

        Raises
        ------
        DriveCommunicationError
            No SYNC within three periods, or the RPDO missed the SYNC it was meant for (a
            SYNC went by meanwhile: the rows would no longer match the commands).
        """
        period = self.sync_period_s
        try:
            self._start_sync_task()
            seen = self.sync_index
            self.network.send_message(cob, payload)
            if not self._wait_until(time.monotonic() + 3 * period + 0.05,
                                    lambda: self.sync_index > seen):
                raise DriveCommunicationError(
                    f"node {self.node_id}: no SYNC from the {self.station.sync_producer} "
                    f"producer for {3 * period + 0.05:.3g} s")
            if self._aligned and self.sync_index > seen + 1:
                raise DriveCommunicationError(
                    f"node {self.node_id}: SYNC {seen + 1} of the {self.station.sync_producer} "
                    "producer went by "
                    "before the host's RPDO for it (the host fell behind its bus)")
            index = self.sync_index
            return self._wait_until(time.monotonic() + period / 2,
                                    lambda: index in self.rx1 and index in self.rx2)
        except can.CanError as exc:
            raise DriveCommunicationError(f"CAN error on node {self.node_id}'s bus: {exc}") from exc

    @contextmanager
    def aligned_to_sync(self) -> Iterator[None]:
        """A streamed run under a SYNC producer other than the host (inside
        :meth:`direct_receive`): it starts right after a SYNC and its answer, so that the
        first RPDO meets the next SYNC, and every tick must meet the SYNC after the last
        (no-op under the host's SYNC)."""
        if not self._observed:
            yield
            return
        self._start_sync_task()
        seen = self.sync_index
        period = self.sync_period_s
        if not self._wait_until(time.monotonic() + 3 * period + 0.05,
                                lambda: self.sync_index > seen):
            raise DriveCommunicationError(
                f"node {self.node_id}: no SYNC from the {self.station.sync_producer} producer "
                f"for {3 * period + 0.05:.3g} s")
        index = self.sync_index
        self._wait_until(time.monotonic() + period / 2,
                         lambda: index in self.rx1 and index in self.rx2)
        self._aligned = True
        try:
            yield
        finally:
            self._aligned = False

    def _wait_until(self, until: float, done: Callable[[], bool]) -> bool:
        """Receive (ourselves in direct mode) until ``done()`` or ``until``."""
        while not done():
            remaining = until - time.monotonic()
            if remaining <= 0:
                return False
            if not self._direct:
                self._progress.wait(min(remaining, 0.002))
                self._progress.clear()
                continue
            bus = self.network.bus
            assert bus is not None
            msg = bus.recv(remaining)
            if msg is not None and not (msg.is_error_frame or msg.is_remote_frame):
                self.network.notify(msg.arbitration_id, msg.data, msg.timestamp)
        return True

    def _wait(self, until: float, *, until_answered: bool) -> bool:
        """Wait for this SYNC's TPDOs (or just for ``until``), receiving ourselves when in
        direct mode (one thread hand-off less per cycle than the Notifier)."""
        if not self._direct:
            if until_answered:
                return self._answered.wait(max(0.0, until - time.monotonic()))
            _sleep_until(until)
            return False
        bus = self.network.bus
        assert bus is not None
        while True:
            remaining = until - time.monotonic()
            if remaining <= 0:
                return False
            msg = bus.recv(remaining)
            if msg is None:
                return False
            if msg.is_error_frame or msg.is_remote_frame:
                continue
            self.network.notify(msg.arbitration_id, msg.data, msg.timestamp)
            if until_answered and self._answered.is_set():
                return True

    def _barrier(self) -> None:
        """An SDO upload of the statusword, its answer awaited up to the SDO timeout: the
        node answers it after whatever it sent before (frames arrive in order)."""
        if not self._direct:
            try:
                self.read(0x6041)  # the Notifier files the earlier TPDOs first
            except (DriveCommunicationError, DriveStateError) as exc:
                log.debug("node %d: no SDO answer after a late SYNC: %s", self.node_id, exc)
            return
        bus = self.network.bus
        assert bus is not None
        response = 0x580 + self.node_id
        self.network.send_message(0x600 + self.node_id, _UPLOAD_STATUSWORD)
        deadline = time.monotonic() + self.station.sdo_timeout_s
        while (remaining := deadline - time.monotonic()) > 0:
            msg = bus.recv(remaining)
            if msg is None:
                return
            if msg.is_error_frame or msg.is_remote_frame:
                continue
            if msg.arbitration_id == response:
                return  # ours alone: no SDO client is waiting for it
            self.network.notify(msg.arbitration_id, msg.data, msg.timestamp)

    @contextmanager
    def direct_receive(self) -> Iterator[None]:
        """Receive in the calling thread (no Notifier) for the duration of a run."""
        network = self.network
        if network.notifier is not None:
            network.notifier.stop(1.0)
            network.check()
        self._direct = True
        try:
            yield
        finally:
            self._direct = False
            if self._connected and network.bus is not None:
                network.notifier = can.Notifier(network.bus, network.listeners, 0.05)

    def latest_status(self) -> tuple[int, int] | None:
        """(statusword, mode display) of the last SYNC, if its TPDO1 arrived."""
        data = self.rx1.get(self.sync_index)
        if data is None:
            return None
        statusword, _, mode = _TPDO1.unpack(data)
        return int(statusword), int(mode)

    def tick_until(self, what: str, done: Callable[[int, int], bool]) -> tuple[int, int]:
        """Tick until ``done(statusword, mode_display)`` holds; fail on fault or timeout."""
        deadline = time.monotonic() + self.station.state_timeout_s
        last: tuple[int, int] | None = None
        while True:
            answered = self.tick()
            self.check()
            if answered:
                last = self.latest_status() or last
            else:  # TPDOs missing: ask by SDO rather than wait for a lost PDO
                last = int(self.read(0x6041)), int(self.read(0x6061))
            if last is not None and done(*last):
                return last
            if time.monotonic() > deadline:
                seen = (
                    "no statusword"
                    if last is None
                    else (f"statusword 0x{last[0]:04X} ({state_of(last[0])}), mode {last[1]}")
                )
                raise DriveStateError(f"node {self.node_id}: {what} not confirmed ({seen})")

    def fault_code(self) -> int:
        """0x603F, else the last EMCY code, else 0."""
        try:
            code = int(self.read(0x603F))
        except (DriveCommunicationError, DriveStateError):
            code = 0
        if not code and self.emcy:
            code = self.emcy[-1][0]
        return code

    def raise_if_faulted(self, statusword: int, context: str) -> None:
        """Raise :class:`DriveFaultError` (code from EMCY or 0x603F) on a fault bit or EMCY."""
        if statusword & SW_FAULT or self.emcy:
            code = self.emcy[-1][0] if self.emcy else self.fault_code()
            raise DriveFaultError(f"node {self.node_id} faulted {context}", code=code)

    def decode(
        self, indices: list[int]
    ) -> tuple[list[tuple[int, int, int]], list[tuple[int, int, int]]]:
        """TPDO1/TPDO2 contents for the given SYNC indices (both must be present)."""
        one = [_TPDO1.unpack(self.rx1[k]) for k in indices]
        two = [_TPDO2.unpack(self.rx2[k]) for k in indices]
        return one, two

    def forget(self) -> None:
        """Drop the feedback received and the SYNC times so far (before a run)."""
        self.rx1.clear()
        self.rx2.clear()
        self.sync_sent_s.clear()


def sdo_access(node: canopen.RemoteNode, action: Callable[[Any], Any], index: int,
               subindex: int, *, raw: bool = False) -> Any:
    """``action`` on ``node``'s variable ``index:subindex`` (``raw``: on ``None``, for an
    object the EDS does not declare), the SDO's failures as the drive errors.

    Raises
    ------
    DriveStateError
        The node aborted the transfer.
    DriveCommunicationError
        No answer within the SDO timeout, or a CAN error.
    """
    what = f"node {node.id} object 0x{index:04X}:{subindex:02X}"
    try:
        if raw:  # not in the EDS: no variable to look up
            return action(None)
        obj = node.sdo[index]
        var = obj if subindex == 0 and not hasattr(obj, "values") else obj[subindex]
        return action(var)
    except SdoAbortedError as exc:
        raise DriveStateError(f"{what}: SDO aborted ({exc})") from exc
    except SdoCommunicationError as exc:
        raise DriveCommunicationError(f"{what}: {exc}") from exc
    except can.CanError as exc:
        raise DriveCommunicationError(f"{what}: CAN error {exc}") from exc


def sdo_read(node: canopen.RemoteNode, index: int, subindex: int = 0) -> Any:
    """An object's value by SDO upload (errors as :func:`sdo_access`)."""
    return sdo_access(node, lambda var: var.raw, index, subindex)


def sdo_write(node: canopen.RemoteNode, index: int, subindex: int, value: Any) -> None:
    """An object's value by SDO download (errors as :func:`sdo_access`)."""

    def set_raw(var: Any) -> None:
        var.raw = value

    sdo_access(node, set_raw, index, subindex)


def sdo_write_standard(node: canopen.RemoteNode, index: int, subindex: int, code: str,
                       value: int) -> None:
    """A standard object by SDO download; one the node's EDS does not declare as raw bytes
    (``code``: its struct type, little-endian). Errors as :func:`sdo_access`."""
    if index in node.object_dictionary:
        sdo_write(node, index, subindex, value)
        return
    data, sdo = struct.pack("<" + code, value), node.sdo
    sdo_access(node, lambda _: sdo.download(index, subindex, data), index, subindex, raw=True)


def _sleep_until(deadline: float) -> None:
    delay = deadline - time.monotonic()
    if delay > 0:
        time.sleep(delay)
