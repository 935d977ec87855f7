"""A CiA 402 servo drive on a python-can bus, backed by :mod:`plant_sim`.

The emulator is a ``canopen.LocalNode`` serving ``fixtures/gimbal_hil_servo.eds``: SDO
server, NMT slave with heartbeat, EMCY producer, the CiA 402 state machine, RPDOs and
TPDOs as configured (by SDO) in its object dictionary, and a drive recorder with a
waveform table (objects 0x2100/0x2200). Its clock is the SYNC: on each SYNC it latches
its actual values and the synchronous RPDO data received since the previous SYNC, advances
the plant by one communication period towards that target (interpolated linearly over the
period, reached at the next SYNC, or held from this SYNC on: 0x60C0 = 0 / -1), and sends
its synchronous TPDOs with the latched values. The actual values are the last control-loop
sample before the SYNC: position measured at the start of that control period, torque
(0x6077) commanded over it, so a row is one period of the control loop old and its torque
is held over one *control* period (0x2200:6), not over the SYNC period. The
manufacturer-specific 0x2077 (INTEGER16, 0.1 ‰ of 0x6076, PDO-mappable) is the mean of the
torque commanded over the control periods of the last SYNC period, i.e. over
``[t_k − T_sync, t_k]``: anti-aliased, where 0x6077 is a point sample of a 4 kHz signal. A
run over real CAN frames is therefore as fast as the frames go, not as fast as the wall
clock.

Safety objects: the consumer heartbeat time 0x1016 (the host's node and time) and the abort
connection option code 0x6007 (what the drive does when that heartbeat stops: 1 fault, 2
disable voltage, 3 quick stop), watched by a thread of its own on the wall clock; the
software position limits 0x607D and the max motor speed 0x6080 (rpm), checked on the
actual values latched at each SYNC: outside them the drive quick-stops and sets statusword
bit 11 (internal limit active). An EDS that lacks these standard objects gets them here.

It knows nothing about the backend that talks to it.
"""

from __future__ import annotations

import copy
import logging
import math
import struct
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can
import canopen
import numpy as np
from canopen.objectdictionary import (
    INTEGER16,
    UNSIGNED8,
    UNSIGNED32,
    ObjectDictionary,
    ODArray,
    ODVariable,
)
from canopen.sdo.exceptions import SdoAbortedError

from hil.config import builtin_fixture
from hil.drives.canopen_map import ObjectMap
from hil.drives.cia402.emulator_map import COMPENSATION, Addresses, present_under
from hil.drives.cia402.emulator_recorder import RUNNING as RECORDER_RUNNING
from hil.drives.cia402.emulator_recorder import DriveRecorder
from hil.drives.cia402.protocol import TORQUE_OFFSET, unpack_harmonics
from hil.drives.emulator_faults import CanFaults
from hil.motion import Mode, PositionHarmonic
from plant_sim.firmware import Firmware
from plant_sim.model import Plant, PlantTrace
from plant_sim.params import Harmonic, PlantParams

log = logging.getLogger(__name__)

EDS_NAME = "gimbal_hil_servo.eds"
ABORT_VALUE_RANGE = 0x06090030
ABORT_NOT_NOW = 0x08000022  # data cannot be transferred because of the device state
SYNC_GENERATE = 0x40000000  # 0x1005 bit 30: the node generates the SYNC
INTERPOLATION_LINEAR, INTERPOLATION_HOLD = 0, -1  # 0x60C0 (negative: manufacturer-specific)
TORQUE_MEAN = 0x2077  # mean torque over the last SYNC period, 0.1 ‰ of 0x6076
TORQUE_MEAN_PER_RATED = 1e4  # 0x2077 counts per rated torque
HEARTBEAT_ERROR = 0x8130  # EMCY: life guard or heartbeat error (CiA 301)
SW_INTERNAL_LIMIT = 0x0800  # statusword bit 11: internal limit active
WATCH_TICK_S = 0.01  # the heartbeat consumer's check period
STALL_S = 0.05  # a check this late: the emulator itself was not running (host overload)
ABORT_FAULT, ABORT_DISABLE_VOLTAGE, ABORT_QUICK_STOP = 1, 2, 3  # 0x6007 option codes

# CiA 402 states and the statusword bits the drive reports in each
NOT_READY, SWITCH_ON_DISABLED, READY, SWITCHED_ON, ENABLED, QUICK_STOP, FAULT_REACTION, FAULT = (
    "NOT READY TO SWITCH ON",
    "SWITCH ON DISABLED",
    "READY TO SWITCH ON",
    "SWITCHED ON",
    "OPERATION ENABLED",
    "QUICK STOP ACTIVE",
    "FAULT REACTION ACTIVE",
    "FAULT",
)
_STATUS_BITS = {
    NOT_READY: 0x00,
    SWITCH_ON_DISABLED: 0x60,
    READY: 0x31,
    SWITCHED_ON: 0x33,
    ENABLED: 0x37,
    QUICK_STOP: 0x17,
    FAULT_REACTION: 0x1F,
    FAULT: 0x08,
}
_MODES = {
    1: Mode.POSITION,
    3: Mode.VELOCITY,
    4: Mode.TORQUE,
    8: Mode.POSITION,
    9: Mode.VELOCITY,
    10: Mode.TORQUE,
}
_MODE_BITS = {1: 0x01, 3: 0x04, 4: 0x08, 8: 0x80, 9: 0x100, 10: 0x200}
_FMT = {1: "?", 2: "b", 3: "h", 4: "i", 5: "B", 6: "H", 7: "I"}


def default_eds_path() -> Path:
    return builtin_fixture(EDS_NAME)


class _BusOffFrame(can.Message):  # type: ignore[misc]
    """What the master's interface delivers when its controller went bus-off: reading it
    raises, exactly where a real interface raises inside ``bus.recv``."""

    def __bool__(self) -> bool:
        raise can.CanOperationError("CAN controller is bus-off (injected)")


class Cia402Emulator:
    """One emulated servo axis on a python-can ``virtual`` channel (or any python-can bus).

    Parameters
    ----------
    plant : PlantParams
        The simulated axis.
    fs_hz : float
        The drive's control-loop rate (the plant's sample rate), Hz.
    seed : int
        Noise seed of the plant.
    channel : str
        python-can channel to join (``interface`` defaults to ``"virtual"``).
    rated_torque_nm, rated_current_a : float
        Written to 0x6076 (mN·m) and 0x6075 (mA); 0x6077/0x6078 are per-mille of them.
    exact_torque_hold : bool
        The plant's held torque moves the position by its exact double integral, as in
        :class:`~hil.drives.sim.SimDrive` (False: the kernel's legacy half-step advance of
        the motion against the torque, which no drive has).
    interpolation : int
        Initial 0x60C0: 0 linear interpolation of cyclic-synchronous targets over the SYNC
        period, -1 hold each target from its SYNC on.
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
        node_id: int = 5,
        rated_torque_nm: float = 0.5,
        rated_current_a: float | None = None,
        serial_number: int = 1,
        supported_modes: int = 0x038D,
        enable_delay_syncs: int = 2,
        lock_mode_while_enabled: bool = False,
        faults: CanFaults | None = None,
        eds_path: Path | None = None,
        exact_torque_hold: bool = True,
        interpolation: int = 0,
        power_on_heartbeat_ms: int | None = None,
        elevation_of: Callable[[], float] | None = None,
        object_map: ObjectMap | None = None,
        clamp_output_bit: int | None = None,
        network: canopen.Network | None = None,
    ) -> None:
        if exact_torque_hold and not plant.exact_torque_hold:
            plant = plant.with_changes(exact_torque_hold=True)  # the same physics as SimDrive
        self.firmware = firmware or Firmware()
        self.plant = Plant(plant, fs_hz=fs_hz, seed=seed, firmware=self.firmware)
        self.fs_hz = float(fs_hz)
        self.faults = faults or CanFaults()
        self.node_id = node_id
        self.channel = channel
        self.interface = interface
        self.supported_modes = supported_modes
        self.enable_delay_syncs = enable_delay_syncs
        self.lock_mode_while_enabled = lock_mode_while_enabled
        self.counts_per_rev = plant.encoder_counts_per_rev or (1 << 20)
        self.rated_torque_nm = rated_torque_nm
        self.rated_current_a = rated_current_a or rated_torque_nm / plant.torque_constant_nm_a
        self._od = canopen.import_od(str(eds_path or default_eds_path()), node_id)
        _add_safety_objects(self._od)
        # presented as the drive model the map describes (None: as its own EDS says)
        self.object_map = object_map
        # the bench's locked-rotor clamp, wired to this digital output (0x60FE:01)
        self.clamp_output_bit = clamp_output_bit
        self.shaft_torque_nm = 0.0  # what a shaft torque transducer reads (clamped)
        self._addresses = present_under(self._od, object_map) if object_map else Addresses()
        self._torque_mean_per_rated = (TORQUE_MEAN_PER_RATED if object_map is None or
                                       object_map.torque_mean is None
                                       else object_map.torque_mean.per_unit)
        self._units = (1e3, 1e3) if object_map is None else (object_map.rated_torque_per_nm,
                                                             object_map.rated_current_per_a)
        velocity = None if object_map is None else object_map.velocity_per_rad_s
        self.velocity_per_rad_s = velocity or self.counts_per_rev / (2 * math.pi)
        self._serial = serial_number
        self._interpolation_code = interpolation
        self._power_on_heartbeat_ms = power_on_heartbeat_ms  # 0x1017 at boot (None: the EDS)
        self._lock = threading.RLock()
        self._network: canopen.Network | None = None
        # a gimbal's nodes share one connection (one receive thread: every node sees the
        # frames in the order the bus carried them), opened and closed by its owner
        self._shared_network = network
        # what a SYNC runs: this node's own step, or its gimbal's (both nodes as one
        # plant, :mod:`hil.drives.cia402.emulator_gimbal`), subscribed there
        self.sync_handler: Callable[[int, bytearray, float], None] = self._on_sync
        self.coupled = False
        self.node: canopen.LocalNode | None = None
        # drive state
        self.state = SWITCH_ON_DISABLED
        self.mode_display = 0
        self.error_code = 0
        self.controlword = 0
        self.targets: dict[int, int] = {0x60FF: 0, 0x6071: 0, 0x607A: 0, TORQUE_OFFSET: 0}
        self.sync_count = 0
        self.time_enabled_s = 0.0
        self.emcy_sent: list[int] = []
        self._enable_countdown = -1
        self._ramp_velocity = 0.0
        self._profile_velocity = 0.0
        self._profile_torque = 0.0
        self._fault_fired = False
        self._bus_error_fired = False
        self._tpdo_frames = 0
        self._pending: dict[int, int] = {}
        self._rpdos: list[tuple[int, int, list[tuple[int, int, str]]]] = []
        self._tpdos: list[tuple[int, int, list[tuple[int, int, str]]]] = []
        self._last_event: dict[int, bytes] = {}
        self._pdo_dirty = True
        self._sample = {0x6064: 0, 0x606C: 0, 0x6077: 0, 0x6078: 0, TORQUE_MEAN: 0}
        self._next_sample = dict(self._sample)
        self._previous_target: dict[int, float] = {}
        self._raw_cache: dict[tuple[int, int], int] = {}
        # profile position (mode 1): the latched target, the profile's position and speed
        self._pp_target = self._pp_position = self._pp_velocity = 0.0
        self._setpoint_acknowledged = False
        # another node's position is this axis's elevation (a gimbal on one bus: the
        # azimuth inertia follows the elevation axis, J_az(el))
        self._elevation_of = elevation_of
        self.held_nodes: dict[str, Cia402Emulator] = {}  # other nodes started beside it
        # control periods per SYNC and the interpolation ramp over them, one tuple: an SDO
        # write (the bus's thread) drops it while the SYNC thread may be reading it
        self._sync_grid: tuple[int, np.ndarray] | None = None
        self._compensation: dict[int, tuple[PositionHarmonic, ...]] = {1: (), 2: ()}
        self.limit_active = False  # stopped at 0x607D/0x6080 (statusword bit 11)
        self.host_lost = 0  # times the host's heartbeat stopped for the consumer time
        self._host_cob: int | None = None  # the consumed heartbeat's COB-ID
        self._host_seen: float | None = None  # monotonic time of its last heartbeat
        self._watch_stop = threading.Event()
        self._watcher: threading.Thread | None = None
        self._producing = threading.Event()  # 0x1005 bit 30: this node sends the SYNC
        self._producer: threading.Thread | None = None
        self.recorder = DriveRecorder(
            capacity=16384,
            loop_period_us=round(1e6 / fs_hz),
            counts_per_rad=self.counts_per_rev / (2 * math.pi),
            velocity_per_rad_s=self.velocity_per_rad_s,
            rated_torque_nm=self.rated_torque_nm,
            rated_current_a=self.rated_current_a,
        )

    # -- life cycle ------------------------------------------------------------------
    def start(self) -> None:
        # the plant's compiled kernel (numba, cached on disk) compiles at its first run: on
        # a fresh checkout that took seconds inside the first SYNC, beyond the master's PDO
        # and SDO timeouts. A copy runs it here, the plant itself untouched.
        copy.deepcopy(self.plant).run(Mode.TORQUE, np.zeros(1))
        network = self._shared_network
        if network is None:
            network = canopen.Network()
            network.connect(interface=self.interface, channel=self.channel, bitrate=1_000_000)
        node = canopen.LocalNode(self.node_id, self._od)
        network.add_node(node)
        self._network, self.node = network, node
        store = node.data_store
        store.setdefault(0x1018, {})[4] = struct.pack("<I", self._serial)
        store.setdefault(0x100A, {})[0] = self.firmware.version.encode("utf-8")
        torque_per_nm, current_per_a = self._units
        store.setdefault(0x6076, {})[0] = struct.pack("<I", round(self.rated_torque_nm
                                                                  * torque_per_nm))
        store.setdefault(0x6075, {})[0] = struct.pack("<I", round(self.rated_current_a
                                                                  * current_per_a))
        store.setdefault(0x608F, {})[1] = struct.pack("<I", self.counts_per_rev)
        store.setdefault(0x60C0, {})[0] = struct.pack("<h", self._interpolation_code)
        if self._power_on_heartbeat_ms is not None:  # 0: no heartbeat until 0x1017 is set
            store.setdefault(0x1017, {})[0] = struct.pack("<H", self._power_on_heartbeat_ms)
        node.add_read_callback(self._on_read)  # type: ignore[no-untyped-call]
        node.add_write_callback(self._on_write)  # type: ignore[no-untyped-call]
        if self.faults.sdo_delay_s > 0:
            network.unsubscribe(node.sdo.rx_cobid, node.sdo.on_request)
            network.subscribe(node.sdo.rx_cobid, self._delayed_sdo)
        if not self.coupled:
            network.subscribe(0x80, self._on_sync)
        network.subscribe(0, self._on_nmt)
        for n in range(4):
            network.subscribe(0x200 + 0x100 * n + self.node_id, self._on_rpdo)
        node.nmt.send_command(0x81)  # reset: boot-up message
        node.nmt.send_command(0x80)  # PRE-OPERATIONAL, heartbeat starts (0x1017)
        self._watch_stop.clear()
        self._watcher = threading.Thread(target=self._watch_host, name="cia402-heartbeat-consumer",
                                         daemon=True)
        self._watcher.start()
        log.info("CiA 402 emulator node %d up on %s", self.node_id, self.channel)

    def _produce_sync(self, on: bool) -> None:
        """Start or stop sending the SYNC (CiA 301 0x1005 bit 30) every 0x1006 µs, on the
        wall clock, this node answering its own SYNC as the others do."""
        if not on:
            self._producing.clear()
            return
        if self._producing.is_set():
            return
        self._producing.set()
        self._producer = threading.Thread(target=self._send_syncs, name="cia402-sync-producer",
                                          daemon=True)
        self._producer.start()

    def _send_syncs(self) -> None:
        deadline = time.monotonic()
        while self._producing.is_set() and self._network is not None:
            deadline += max(self._raw(0x1006), 100) * 1e-6
            delay = deadline - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                deadline = time.monotonic()  # behind: resynchronise
            network = self._network
            if network is None or not self._producing.is_set():
                return
            network.send_message(0x80, b"")
            self.sync_handler(0x80, bytearray(), time.time())

    def stop(self) -> None:
        self._producing.clear()
        if self._producer is not None:
            self._producer.join(1.0)
            self._producer = None
        self._watch_stop.set()
        if self._watcher is not None:
            self._watcher.join(1.0)
            self._watcher = None
        if self._network is not None and self.node is not None:
            self.node.nmt.stop_heartbeat()  # type: ignore[no-untyped-call]
            if self._shared_network is None:
                self._network.disconnect()
        self._network = None

    def __enter__(self) -> Cia402Emulator:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def nmt_state(self) -> str:
        return "STOPPED" if self.node is None else str(self.node.nmt.state)

    @property
    def statusword(self) -> int:
        word = _STATUS_BITS[self.state] | 0x0200  # remote
        if self.limit_active:
            word |= SW_INTERNAL_LIMIT
        if self.state == ENABLED and self.mode_display in (8, 9, 10):
            word |= 0x1000  # drive follows the command value
        if self.state == ENABLED and self.mode_display == 1:
            word |= 0x1000 if self._setpoint_acknowledged else 0
            word |= 0x0400 if self._target_reached() else 0
        if self.state == SWITCH_ON_DISABLED:
            word &= ~0x20 & 0xFFFF
        return word

    # -- object access -----------------------------------------------------------------
    def _on_read(self, *, index: int, subindex: int, od: ODVariable) -> Any:
        index, subindex = self._addresses.native(index, subindex)
        with self._lock:
            if index == 0x6041:
                return self.statusword
            if index == 0x6061:
                return self.mode_display
            if index == 0x603F:
                return self.error_code
            if index == 0x6502:
                return self.supported_modes
            if index == 0x1001:
                return self._error_register()
            if index in self._sample:
                return self._sample[index]
            if index in self.targets:
                return self.targets[index]
            if index in (0x2100, 0x2200):
                return self.recorder.read(index, subindex)
        return None

    def _on_write(self, *, index: int, subindex: int, od: ODVariable, data: bytes) -> None:
        self._sync_grid = None
        value: Any = data
        if od.data_type in _FMT:
            value = struct.unpack("<" + _FMT[od.data_type], data)[0]
        with self._lock:
            self._write_checked(*self._addresses.native(index, subindex), value)
            if od.data_type in _FMT:  # the store is written after this callback
                self._raw_cache[(index, subindex)] = int(value)

    def _write_checked(self, index: int, subindex: int, value: Any) -> None:
        if 0x1400 <= index < 0x1C00:
            if self.nmt_state == "OPERATIONAL" and subindex != 2:
                raise SdoAbortedError(ABORT_NOT_NOW)
            self._pdo_dirty = True
        elif index == 0x6040:
            self._apply_controlword(int(value))
        elif index == 0x6060:
            if value not in _MODE_BITS or not self.supported_modes & _MODE_BITS[value]:
                raise SdoAbortedError(ABORT_VALUE_RANGE)
            if not (self.lock_mode_while_enabled and self.state == ENABLED):
                self.mode_display = int(value)
        elif index in self.targets:
            self.targets[index] = int(value)
        elif index == 0x60C2 or index == 0x1006:
            self._check_period(index, subindex, int(value))
        elif index == 0x60C0 and value not in (INTERPOLATION_LINEAR, INTERPOLATION_HOLD):
            raise SdoAbortedError(ABORT_VALUE_RANGE)
        elif index == 0x1016 and subindex == 1:
            self._consume_heartbeat(int(value))
        elif index == 0x1005:
            self._produce_sync(bool(int(value) & SYNC_GENERATE))
        elif index == 0x60FE and subindex == 1 and self.clamp_output_bit is not None:
            self.plant.set_locked_rotor(bool(int(value) >> self.clamp_output_bit & 1))
        elif index in (0x2100, 0x2200):
            self.recorder.write(index, subindex, value, running=self.state == ENABLED)
        elif index == COMPENSATION and subindex in (1, 2):
            try:
                self._compensation[subindex] = unpack_harmonics(bytes(value))
            except (ValueError, struct.error):
                raise SdoAbortedError(ABORT_VALUE_RANGE) from None
            self.plant.load_compensation(*(_harmonics(self._compensation[s]) for s in (1, 2)))

    def _check_period(self, index: int, subindex: int, value: int) -> None:
        """0x1006 (µs) must be a whole number of control periods; 0x60C2 is taken as is."""
        if index != 0x1006 or value == 0:
            return
        steps = value * 1e-6 * self.fs_hz
        if steps < 1 - 1e-9 or abs(steps - round(steps)) > 1e-6:
            raise SdoAbortedError(ABORT_VALUE_RANGE)

    def _raw(self, index: int, subindex: int = 0) -> int:
        """An integer object's value (cached until the next write to it)."""
        cached = self._raw_cache.get((index, subindex))
        if cached is not None:
            return cached
        assert self.node is not None
        obj = self._od[index]
        var = obj if isinstance(obj, ODVariable) else obj[subindex]
        data = self.node.get_data(index, subindex)
        value = int(struct.unpack("<" + _FMT[var.data_type], data)[0])  # type: ignore[index]
        if not var.writable or index not in (0x6041, 0x6061, 0x603F):
            self._raw_cache[(index, subindex)] = value
        return value

    def _interpolation(self) -> tuple[int, int]:
        return self._raw(0x60C2, 1), self._raw(0x60C2, 2)

    def steps_per_sync(self) -> int:
        """Control periods per SYNC: 0x1006 when set, else 0x60C2."""
        return self._grid()[0]

    def _grid(self) -> tuple[int, np.ndarray]:
        """Control periods per SYNC and the linear interpolation's ramp over them, read
        once into a local: a write between two reads of the attribute left a SYNC with no
        periods (an intermittent CI failure: the SYNC thread died and the run lost its
        SYNC)."""
        grid = self._sync_grid
        if grid is None:
            steps = self._steps_per_sync()
            grid = (steps, np.arange(1, steps + 1) / steps)
            self._sync_grid = grid
        return grid

    def _steps_per_sync(self) -> int:
        cycle_us = self._raw(0x1006)
        if cycle_us:
            return max(1, round(cycle_us * 1e-6 * self.fs_hz))
        mantissa, exponent = self._interpolation()
        return max(1, round(mantissa * 10.0**exponent * self.fs_hz))

    def _error_register(self) -> int:
        if not self.error_code:
            return 0
        return 0x01 | (0x02 if self.error_code & 0xF000 == 0x2000 else 0)

    # -- state machine -----------------------------------------------------------------
    def _apply_controlword(self, word: int) -> None:
        rising_reset = bool(word & 0x80) and not self.controlword & 0x80
        new_setpoint = bool(word & 0x10) and not self.controlword & 0x10
        self.controlword = word
        self._setpoint_acknowledged = bool(word & 0x10) and self._setpoint_acknowledged
        if new_setpoint and self.state == ENABLED and self.mode_display == 1:
            self._pp_target = self.targets[0x607A] / self._counts_per_rad
            self._setpoint_acknowledged = True
        state = self.state
        if state in (FAULT, FAULT_REACTION):
            if rising_reset and state == FAULT and not self.faults.fault_persists:
                self.error_code = 0
                self.state = SWITCH_ON_DISABLED
                self._emcy(0x0000)
            return
        command = word & 0x0F
        if not command & 0x02:  # disable voltage
            self._enter(SWITCH_ON_DISABLED)
        elif not command & 0x04:  # quick stop
            if state == ENABLED:
                self._quick_stop()
            elif state in (READY, SWITCHED_ON):
                self._enter(SWITCH_ON_DISABLED)
        elif command & 0x07 == 0x06:  # shutdown
            if state in (SWITCH_ON_DISABLED, SWITCHED_ON, ENABLED):
                self._enter(READY)
        elif command == 0x07:  # switch on
            if state in (READY, ENABLED):
                self._enter(SWITCHED_ON)
        elif command == 0x0F:  # enable operation
            if state == READY:
                self._enter(SWITCHED_ON)
            if self.state == SWITCHED_ON and self._enable_countdown < 0:
                self._enable_countdown = self.enable_delay_syncs
                if self._enable_countdown == 0:
                    self._enter(ENABLED)
            elif state == QUICK_STOP and self._quick_stop_option() >= 5:
                self._enter(ENABLED)

    def _enter(self, state: str) -> None:
        if state == self.state:
            return
        log.debug("emulator node %d: %s -> %s", self.node_id, self.state, state)
        if state == ENABLED:
            self.limit_active = False
            self._previous_target = {}
            self.plant.hold()
            self._pp_target = self._pp_position = self.plant.position_rad  # holds where it is
            self._pp_velocity = 0.0
            self._profile_velocity = self.plant.velocity_rad_s
            self._profile_torque = 0.0
        self._enable_countdown = -1
        self.state = state
        self._send_event_tpdos()

    def _quick_stop_option(self) -> int:
        return self._raw(0x605A)

    def _quick_stop(self) -> None:
        option = self._quick_stop_option()
        if option == 0:
            self._enter(SWITCH_ON_DISABLED)
            return
        self._ramp_velocity = self.plant.velocity_rad_s
        self._enter(QUICK_STOP)

    def _trip(self, code: int) -> None:
        self.error_code = code
        self.state = FAULT
        self._enable_countdown = -1
        self._emcy(code)
        self._send_event_tpdos()

    def _emcy(self, code: int) -> None:
        if self.node is not None and self._network is not None:
            self.emcy_sent.append(code)
            self.node.emcy.send(code, self._error_register())

    # -- safety: the host's heartbeat, the drive's own limits ----------------------------
    def _consume_heartbeat(self, entry: int) -> None:
        """0x1016:1 written: watch node ``entry >> 16``'s heartbeat (time ``entry & 0xFFFF``
        ms; 0 is off). Monitoring starts with its first heartbeat (CiA 301)."""
        if self._network is None:
            return
        if self._host_cob is not None:
            self._network.unsubscribe(self._host_cob, self._on_host_heartbeat)
            self._host_cob = None
        self._host_seen = None
        node, time_ms = (entry >> 16) & 0x7F, entry & 0xFFFF
        if node and time_ms:
            self._host_cob = 0x700 + node
            self._network.subscribe(self._host_cob, self._on_host_heartbeat)

    def _on_host_heartbeat(self, can_id: int, data: bytearray, timestamp: float) -> None:
        with self._lock:
            if can_id == self._host_cob:
                self._host_seen = time.monotonic()

    def _watch_host(self) -> None:
        """The heartbeat consumer, on the wall clock (a thread of its own: a dead host sends
        no SYNC either). Time the emulator itself was not scheduled is not host silence."""
        last = time.monotonic()
        while not self._watch_stop.wait(WATCH_TICK_S):
            now = time.monotonic()
            late, last = now - last - WATCH_TICK_S, now
            with self._lock:
                if self._host_seen is None or self._host_cob is None:
                    continue
                if late > STALL_S:
                    self._host_seen += late
                timeout_s = (self._raw(0x1016, 1) & 0xFFFF) * 1e-3
                if now - self._host_seen > timeout_s:
                    self._host_seen = None  # again armed by the next heartbeat
                    self._host_lost(timeout_s)

    def _host_lost(self, timeout_s: float) -> None:
        """The host's heartbeat stopped: EMCY 0x8130, then the abort connection option."""
        option = self._raw(0x6007)
        self.host_lost += 1
        log.warning("emulator node %d: no heartbeat from the host for %.3g s: 0x6007 = %d, "
                    "state %s", self.node_id, timeout_s, option, self.state)
        if option == ABORT_FAULT:
            self._trip(HEARTBEAT_ERROR)
            return
        self._emcy(HEARTBEAT_ERROR)
        if option == ABORT_DISABLE_VOLTAGE:
            self._enter(SWITCH_ON_DISABLED)
        elif option == ABORT_QUICK_STOP and self.state == ENABLED:
            self._quick_stop()

    def _check_own_limits(self) -> None:
        """The latched actual values against 0x607D (counts) and 0x6080 (rpm): outside,
        the drive quick-stops and reports internal limit active (statusword bit 11)."""
        position, velocity = self._sample[0x6064], self._sample[0x606C]
        rpm = abs(velocity) / self.velocity_per_rad_s * 60.0 / (2 * math.pi)
        if self._raw(0x607D, 1) <= position <= self._raw(0x607D, 2) and rpm <= self._raw(0x6080):
            return
        log.warning("emulator node %d: at its own limit (position %d counts, %.1f rpm): "
                    "quick stop", self.node_id, position, rpm)
        self.limit_active = True
        self._quick_stop()

    # -- NMT ---------------------------------------------------------------------------
    def _on_nmt(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if len(data) >= 2 and data[1] in (0, self.node_id) and data[0] in (0x80, 0x81, 0x82):
            with self._lock:
                self._pdo_dirty = True
                if data[0] == 0x81:
                    self._enter(SWITCH_ON_DISABLED)

    # -- PDOs --------------------------------------------------------------------------
    def _pdo_tables(self) -> None:
        """Rebuild the RPDO/TPDO tables from the object dictionary (after any change)."""
        if not self._pdo_dirty:
            return
        self._rpdos, self._tpdos = [], []
        self._formats: dict[int, struct.Struct] = {}
        for comm, mapping, out in ((0x1400, 0x1600, self._rpdos), (0x1800, 0x1A00, self._tpdos)):
            for n in range(4):
                if comm + n not in self._od:
                    continue
                cob = self._raw(comm + n, 1)
                if cob & 0x80000000:
                    continue
                entries = []
                for sub in range(1, self._raw(mapping + n, 0) + 1):
                    word = self._raw(mapping + n, sub)
                    index, subindex, bits = word >> 16, (word >> 8) & 0xFF, word & 0xFF
                    obj = self._od[index]
                    var = obj if isinstance(obj, ODVariable) else obj[subindex]
                    if bits != len(var):
                        raise SdoAbortedError(0x06040042)
                    own = self._addresses.native(index, subindex)
                    entries.append((*own, _FMT[var.data_type]))  # type: ignore[index]
                out.append((cob & 0x7FF, self._raw(comm + n, 2), entries))
        self._pdo_dirty = False

    def _on_rpdo(self, can_id: int, data: bytearray, timestamp: float) -> None:
        with self._lock:
            if self.nmt_state != "OPERATIONAL":
                return
            self._pdo_tables()
            for cob, trans, entries in self._rpdos:
                if cob != can_id:
                    continue
                fmt = "<" + "".join(e[2] for e in entries)
                if struct.calcsize(fmt) != len(data):
                    return  # wrong length: ignored (a real drive would send EMCY 0x8210)
                values = dict(zip((e[0] for e in entries), struct.unpack(fmt, data), strict=True))
                if trans <= 240:
                    self._pending.update(values)
                else:
                    self._apply(values)

    def _apply(self, values: dict[int, int]) -> None:
        for index, value in values.items():
            if index == 0x6040:
                self._apply_controlword(value)
            elif index == 0x6060:
                if value in _MODE_BITS and self.supported_modes & _MODE_BITS[value]:
                    self.mode_display = value
            elif index in self.targets:
                self.targets[index] = value

    def _pack(self, entries: list[tuple[int, int, str]]) -> bytes:
        live = {
            0x6041: self.statusword,
            0x6061: self.mode_display,
            0x603F: self.error_code,
            0x1001: self._error_register(),
        }
        values = []
        for index, subindex, _ in entries:
            if index in live:
                values.append(live[index])
            elif index == 0x2200:
                values.append(int(self.recorder.read(index, subindex)))
            else:
                values.append(self._sample.get(index, self.targets.get(index, 0)))
        fmt = self._formats.get(id(entries))
        if fmt is None:
            fmt = self._formats[id(entries)] = struct.Struct("<" + "".join(e[2] for e in entries))
        return fmt.pack(*values)

    def _send_tpdo(self, cob: int, payload: bytes) -> None:
        assert self._network is not None
        self._tpdo_frames += 1
        drop_every = self.faults.drop_tpdo_every
        if drop_every and self._tpdo_frames % drop_every == 0:
            return
        cutoff = self.faults.drop_all_tpdo_after_s
        if cutoff is not None and self.time_enabled_s >= cutoff:
            return
        self._network.send_message(cob, payload)

    def _send_event_tpdos(self) -> None:
        if self._network is None or self.nmt_state != "OPERATIONAL":
            return
        self._pdo_tables()
        for cob, trans, entries in self._tpdos:
            if trans >= 254:
                payload = self._pack(entries)
                if self._last_event.get(cob) != payload:
                    self._last_event[cob] = payload
                    self._send_tpdo(cob, payload)

    # -- the clock -----------------------------------------------------------------------
    def _on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        with self._lock:
            operational = self.latch()
            steps, ramp = self._grid()
            self._follow_elevation()
            mode, command, offset = self.block(steps, ramp)
            self.finish(self.plant.run(mode, command, offset), steps)
            self.publish(operational)

    # the SYNC's phases (a gimbal runs them for both nodes around one step of both axes)
    def latch(self) -> bool:
        """At the SYNC: the actual values latched, the synchronous RPDOs' data applied, the
        enable delay counted, the drive's own limits checked; whether it is OPERATIONAL."""
        self.sync_count += 1
        self._sample = self._next_sample  # actual values latched at this SYNC
        operational = self.nmt_state == "OPERATIONAL"
        if operational and self._pending:
            pending, self._pending = self._pending, {}
            self._apply(pending)
        if self._enable_countdown > 0:
            self._enable_countdown -= 1
        if self._enable_countdown == 0 and self.state == SWITCHED_ON:
            self._enter(ENABLED)
        if self.state == ENABLED:
            self._check_own_limits()
        return operational

    def grid(self) -> tuple[int, np.ndarray]:
        """Control periods per SYNC and the linear interpolation's ramp over them."""
        return self._grid()

    @property
    def period_set(self) -> bool:
        """The host wrote this node's SYNC period (0x1006)."""
        return bool(self._raw(0x1006))

    def block(self, steps: int, ramp: np.ndarray
              ) -> tuple[Mode, np.ndarray, np.ndarray | None]:
        """This SYNC period's command: mode, one sample per control period, torque offset."""
        mode, command = self._command(steps, steps / self.fs_hz, ramp)
        offset = None
        if self.state == ENABLED and mode is Mode.VELOCITY:  # 0x60B2, held over the period
            offset = np.full(steps, self.targets[TORQUE_OFFSET] * self.rated_torque_nm / 1e3)
        return mode, command, offset

    def finish(self, trace: PlantTrace, steps: int) -> None:
        """After the plant moved through the period: the recorder's capture, what the
        drive latches at the next SYNC, the state's timers."""
        period_s = steps / self.fs_hz
        playing = self.recorder.status == RECORDER_RUNNING
        self.recorder.capture(trace, enabled=self.state == ENABLED)
        if playing and self.recorder.status != RECORDER_RUNNING and self.mode_display == 1:
            # profile position after a table: the profile holds where the table ended
            self._pp_target = self._pp_position = self.recorder.last_target / self._counts_per_rad
            self._pp_velocity = 0.0
        shaft = trace.load_torque_nm  # the transducer between the clamp and the shaft
        self.shaft_torque_nm = 0.0 if shaft is None else float(np.mean(shaft))
        # what the drive latches at the *next* SYNC: its most recent control-loop values
        cpr = self.counts_per_rev
        self._next_sample = {
            0x6064: round(trace.position_rad[-1] * cpr / (2 * math.pi)),
            0x606C: round(trace.velocity_rad_s[-1] * self.velocity_per_rad_s),
            0x6077: _clip16(trace.torque_nm[-1] / self.rated_torque_nm * 1e3),
            0x6078: _clip16(trace.current_a[-1] / self.rated_current_a * 1e3),
            # the mean over this SYNC period's control samples (each held over one period)
            TORQUE_MEAN: _clip16(
                float(np.mean(trace.torque_nm)) / self.rated_torque_nm
                * self._torque_mean_per_rated
            ),
        }
        if self.state == ENABLED:
            self.time_enabled_s += period_s
            after = self.faults.emcy_after_s
            if after is not None and not self._fault_fired and self.time_enabled_s >= after:
                self._fault_fired = True
                self._trip(self.faults.emcy_code)
        elif (
            self.state == QUICK_STOP
            and self._ramp_velocity == 0.0
            and abs(self.plant.velocity_rad_s) < 1e-3
            and self._quick_stop_option() < 5
        ):
            self._enter(SWITCH_ON_DISABLED)

    def publish(self, operational: bool) -> None:
        """The synchronous TPDOs with the latched values, and any event-driven ones."""
        if not operational:
            return
        self._pdo_tables()
        for cob, trans, entries in self._tpdos:
            if 1 <= trans <= 240 and self.sync_count % trans == 0:
                self._send_tpdo(cob, self._pack(entries))
        self._send_event_tpdos()
        self._inject_bus_error()

    @property
    def lock(self) -> threading.RLock:
        """Held while a SYNC or a request changes the drive."""
        return self._lock

    def _command(self, steps: int, period_s: float,
                 ramp: np.ndarray) -> tuple[Mode, np.ndarray]:
        cpr = self.counts_per_rev
        if self.state == QUICK_STOP:
            decel = self._raw(0x6085) / self.velocity_per_rad_s
            step = min(decel * period_s, abs(self._ramp_velocity))
            self._ramp_velocity -= math.copysign(step, self._ramp_velocity)
            return Mode.VELOCITY, np.full(steps, self._ramp_velocity)
        if self.state != ENABLED or self.mode_display not in _MODES:
            return Mode.TORQUE, np.zeros(steps)
        waveform = self.recorder.waveform_block(steps)
        mode = _MODES[self.mode_display]
        if waveform is None and self.mode_display == 1:
            return mode, self._profile_position(steps)
        if waveform is None and self.mode_display in (8, 9, 10):
            # cyclic synchronous modes: the target latched at this SYNC is reached at the
            # next one; 0x60C0 = 0 (CiA 402 linear interpolation) ramps to it over the period,
            # -1 (manufacturer-specific) holds it from this SYNC on
            index = {Mode.VELOCITY: 0x60FF, Mode.TORQUE: 0x6071, Mode.POSITION: 0x607A}[mode]
            new = float(self.targets[index])
            old = self._previous_target.get(index, new)
            self._previous_target = {index: new}
            if self._raw(0x60C0) == INTERPOLATION_HOLD:
                waveform = np.full(steps, new)
            else:
                waveform = old + (new - old) * ramp
        if mode is Mode.VELOCITY:
            raw = self.targets[0x60FF] if waveform is None else waveform
            value = np.asarray(raw, dtype=np.float64) / self.velocity_per_rad_s
            if self.mode_display == 3:  # profile velocity: ramp at 0x6083
                accel = self._raw(0x6083) * 2 * math.pi / cpr * period_s
                target = float(np.mean(value))
                self._profile_velocity += float(
                    np.clip(target - self._profile_velocity, -accel, accel)
                )
                value = np.asarray(self._profile_velocity)
            return mode, np.broadcast_to(value, (steps,)).copy()
        if mode is Mode.TORQUE:
            raw = self.targets[0x6071] if waveform is None else waveform
            value = np.asarray(raw, dtype=np.float64) * self.rated_torque_nm / 1e3
            if self.mode_display == 4:  # profile torque: slope 0x6087 (per-mille/s)
                slope = self._raw(0x6087) * self.rated_torque_nm / 1e3 * period_s
                target = float(np.mean(value))
                self._profile_torque += float(np.clip(target - self._profile_torque, -slope, slope))
                value = np.asarray(self._profile_torque)
            limit = self._raw(0x6072) * self.rated_torque_nm / 1e3
            return mode, np.clip(np.broadcast_to(value, (steps,)), -limit, limit)
        raw = self.targets[0x607A] if waveform is None else waveform
        value = np.asarray(raw, dtype=np.float64) * 2 * math.pi / cpr
        return mode, np.broadcast_to(value, (steps,)).copy()

    @property
    def _counts_per_rad(self) -> float:
        return self.counts_per_rev / (2 * math.pi)

    def _profile_position(self, steps: int) -> np.ndarray:
        """Profile position (mode 1): toward the latched target at the profile velocity
        0x6081, accelerating at 0x6083 and braking at 0x6084 (increments/s, /s²), one
        position per control period; the position loop follows it."""
        scale, dt = self._counts_per_rad, 1.0 / self.fs_hz
        top = self._raw(0x6081) / scale
        accel, brake = self._raw(0x6083) / scale, max(self._raw(0x6084) / scale, 1e-9)
        path = np.empty(steps)
        position, velocity, target = self._pp_position, self._pp_velocity, self._pp_target
        for i in range(steps):
            remaining = target - position
            if velocity * remaining < 0:  # heading away (a new target behind): brake first
                velocity -= math.copysign(min(brake * dt, abs(velocity)), velocity)
            else:
                speed = min(top, math.sqrt(2.0 * brake * abs(remaining)),
                            abs(velocity) + accel * dt)
                velocity = math.copysign(speed, remaining)
            if abs(remaining) <= abs(velocity) * dt:
                position, velocity = target, 0.0
            else:
                position += velocity * dt
            path[i] = position
        self._pp_position, self._pp_velocity = position, velocity
        return path

    def _target_reached(self) -> bool:
        """Statusword bit 10 in profile position: the profile at its target and the axis
        within the position window 0x6067 of it."""
        window = self._raw(0x6067) / self._counts_per_rad
        return (self._pp_position == self._pp_target
                and abs(self.plant.position_rad - self._pp_target) <= window)

    def follow_elevation_of(self, elevation_of: Callable[[], float]) -> None:
        """Have this axis's J follow ``elevation_of()`` at each SYNC (J_az(el))."""
        self._elevation_of = elevation_of

    def _follow_elevation(self) -> None:
        if self._elevation_of is not None:
            self.plant.follow_elevation(self._elevation_of())

    def _inject_bus_error(self) -> None:
        after = self.faults.bus_error_after_s
        if after is None or self._bus_error_fired or self.state != ENABLED:
            return
        if self.time_enabled_s < after:
            return
        self._bus_error_fired = True
        from can.interfaces import virtual

        own = getattr(self._network.bus, "queue", None) if self._network else None
        with virtual.channels_lock:
            for queue in virtual.channels.get(self.channel, []):
                if queue is not own:
                    queue.put(_BusOffFrame(arbitration_id=0, data=b""))
        log.info("emulator node %d: injected a bus-off at the master", self.node_id)

    def _delayed_sdo(self, can_id: int, data: bytearray, timestamp: float) -> None:
        assert self.node is not None
        timer = threading.Timer(
            self.faults.sdo_delay_s, self.node.sdo.on_request, (can_id, bytes(data), timestamp)
        )
        timer.daemon = True
        timer.start()


def _add_safety_objects(od: ObjectDictionary) -> None:
    """The standard objects the drive's safety needs, where the EDS lacks them: 0x1016
    consumer heartbeat time (one entry), 0x6007 abort connection option code, 0x6080 max
    motor speed (rpm); and 0x60FE digital outputs (a bench's clamp)."""
    def variable(name: str, index: int, sub: int, data_type: int, default: int,
                 access: str = "rw") -> ODVariable:
        var = ODVariable(name, index, sub)
        var.data_type, var.access_type, var.default = data_type, access, default
        return var

    if 0x1016 not in od:
        array = ODArray("Consumer heartbeat time", 0x1016)
        array.add_member(variable("Highest sub-index supported", 0x1016, 0, UNSIGNED8, 1, "ro"))
        array.add_member(variable("Consumer heartbeat time", 0x1016, 1, UNSIGNED32, 0))
        od.add_object(array)
    if 0x6007 not in od:
        od.add_object(variable("Abort connection option code", 0x6007, 0, INTEGER16, 1))
    if 0x6080 not in od:
        od.add_object(variable("Max motor speed", 0x6080, 0, UNSIGNED32, 0xFFFFFFFF))
    if 0x60FE not in od:
        outputs = ODArray("Digital outputs", 0x60FE)
        outputs.add_member(variable("Highest sub-index supported", 0x60FE, 0, UNSIGNED8, 2, "ro"))
        outputs.add_member(variable("Physical outputs", 0x60FE, 1, UNSIGNED32, 0))
        outputs.add_member(variable("Bit mask", 0x60FE, 2, UNSIGNED32, 0))
        od.add_object(outputs)


def _harmonics(table: tuple[PositionHarmonic, ...]) -> tuple[Harmonic, ...]:
    return tuple(Harmonic(order=h.order, amplitude=h.amplitude, phase_rad=h.phase_rad)
                 for h in table)


def _clip16(value: float) -> int:
    return int(min(max(round(value), -32768), 32767))
