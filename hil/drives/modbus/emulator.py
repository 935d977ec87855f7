"""A Modbus servo drive (TCP, or RTU framing over a TCP socket) backed by :mod:`plant_sim`.

A pymodbus server on 127.0.0.1 serves the holding registers of the register map it is
given (``fixtures/regmap_*.toml``). Unlike the CANopen emulator, the plant steps in real
time, one control period (``1/fs_hz``) at a time: every request first brings it up to the
wall clock with the last command held (so a read returns a state at most one control
period old, like a real drive's registers), and a background task keeps it going between
requests (and runs the drive's communication watchdog: silence of the master for
``watchdog_s`` trips 0x8130; time the emulator itself was not scheduled does not count,
see ``_credit_own_stall``). With a ``timestamp`` register the
drive's clock (the plant time of the latched feedback, in control periods) is served with
the feedback; with a ``setpoint_interpolation_time`` register a written setpoint is reached
by a linear ramp over that time instead of a step. With a ``torque_mean`` register the drive
serves the mean of the torque commanded per control period over the control periods since
the previous read of that register, up to and including the latched one (a read that
includes its first word restarts the average; a read within the same control period leaves
the latched mean as it was), and ``torque_mean_window`` the length of that average
(periods × control period). Faults: line delay, exception responses,
a drive trip, a dropped connection, a drive that stops answering.
"""

from __future__ import annotations

import asyncio
import logging
import math
import re
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pymodbus import FramerType
from pymodbus.constants import ExcCodes
from pymodbus.datastore import ModbusServerContext
from pymodbus.datastore.context import ModbusBaseDeviceContext
from pymodbus.server import ModbusTcpServer

from hil.drives.emulator_faults import ModbusFaults
from hil.drives.modbus.emulator_recorder import ModbusRecorder
from hil.drives.modbus.regmap import (
    COMPENSATION,
    DIGITAL_OUTPUTS,
    FEEDBACK,
    RECORDER_COLUMNS,
    RECORDER_OFFSET,
    SETPOINT_INTERPOLATION,
    TIMESTAMP,
    TORQUE_MEAN,
    TORQUE_MEAN_WINDOW,
    TORQUE_OFFSET,
    load_register_map,
)
from hil.motion import Mode
from plant_sim.firmware import Firmware
from plant_sim.model import Plant
from plant_sim.params import Harmonic, PlantParams

log = logging.getLogger(__name__)

WATCHDOG_FAULT = 0x8130  # CiA-style "life guard / heartbeat error"
QUICK_STOP_DECEL_RAD_S2 = 20.0
REGISTERS = 128
TICK_S = 0.005  # period of the background task (plant between requests, watchdog)
STALL_S = 0.05  # a tick this late: the emulator itself was not running (host overload)


@dataclass(slots=True)
class _Setpoint:
    """The setpoint the drive's loops see: ``start`` → ``target`` linearly over ``steps``
    control periods from plant step ``begin`` (``steps`` = 0: the target at once)."""

    mode: str | None = None
    start: float = 0.0
    target: float = 0.0
    begin: int = 0
    steps: int = 0

    def values(self, first: int, count: int) -> np.ndarray:
        """The setpoint at plant steps ``first`` … ``first + count - 1``."""
        if self.steps <= 0:
            return np.full(count, self.target)
        done = (first + np.arange(count) - self.begin + 1) / self.steps
        return self.start + (self.target - self.start) * np.clip(done, 0.0, 1.0)


class _Context(ModbusBaseDeviceContext):  # type: ignore[misc]
    def __init__(self, emulator: ModbusEmulator) -> None:
        self.emulator = emulator

    def reset(self) -> None:  # pragma: no cover - required by the interface
        pass

    async def async_getValues(self, func_code: int, address: int, count: int = 1) -> Any:  # noqa: N802
        return await self.emulator.serve(func_code, address, count, None)

    async def async_setValues(  # noqa: N802
        self, func_code: int, address: int, values: list[int] | list[bool]
    ) -> Any:
        return await self.emulator.serve(func_code, address, len(values), [int(v) for v in values])


def version_code(version: str) -> int:
    """The ``firmware_version`` register (major × 256 + minor) of a version string: its
    first ``major.minor`` (``"GMB-2-EL 1.4.0"`` → 0x0104); 0 when it has none."""
    found = re.search(r"(\d+)\.(\d+)", version)
    if found is None:
        return 0
    return min(int(found.group(1)), 255) * 256 + min(int(found.group(2)), 255)


class ModbusEmulator:
    """One emulated servo axis behind a Modbus server on 127.0.0.1 (an ephemeral port)."""

    def __init__(
        self,
        plant: PlantParams,
        *,
        firmware: Firmware | None = None,
        fs_hz: float,
        seed: int,
        register_map: Path,
        rated_torque_nm: float,
        framing: str = "tcp",
        faults: ModbusFaults | None = None,
        serial_number: int = 1,
        watchdog_s: float = 0.5,
        unit_id: int | None = None,
        neighbours: Mapping[int, ModbusEmulator] | None = None,
        elevation_of: Callable[[], float] | None = None,
        clamp_output_bit: int | None = None,
        exact_torque_hold: bool = True,
    ) -> None:
        self.firmware = firmware or Firmware()
        if exact_torque_hold and not plant.exact_torque_hold:
            # the same physics as SimDrive and the CANopen emulator (False: the kernel's
            # legacy half-step advance of the motion against the torque, which no drive
            # has: it took half a control period off τ on the drive recorder)
            plant = plant.with_changes(exact_torque_hold=True)
        self.plant = Plant(plant, fs_hz=fs_hz, seed=seed, firmware=self.firmware)
        self.fs_hz = float(fs_hz)
        self.map = load_register_map(register_map)
        self.rated_torque_nm = rated_torque_nm
        self.framing = framing
        self.faults = faults or ModbusFaults()
        self.watchdog_s = watchdog_s
        self.port = 0
        self.regs = np.zeros(max(REGISTERS, self.map.address_end), dtype=np.int64)
        # the drive recorder, where the map declares one (its rate: the control rate)
        self.recorder = ModbusRecorder(self.map, self.regs) if self.map.has_recorder else None
        self.enabled = False
        self.quick_stopping = False
        self.fault_code = 0
        self.time_enabled_s = 0.0
        self.requests = 0
        self._ramp = 0.0
        self._control = 0
        self._setpoint = _Setpoint()
        self._torque_sum = 0.0  # torque commanded per control period, summed since the
        self._torque_periods = 0  # last read of torque_mean, and how many periods
        self._last_request = time.monotonic()
        self._clock = time.monotonic()
        self._tick = time.monotonic()
        self.stalls = 0  # times the emulator's own loop was held up ≥ STALL_S
        self.longest_stall_s = 0.0
        self._lock = threading.Lock()
        self._dropped = False
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._server: ModbusTcpServer | None = None
        self._ready = threading.Event()
        self._stopping = False
        # a gimbal on one server: this drive at unit_id (None: it answers every unit id),
        # the other axes' drives (not started themselves) at theirs; the elevation
        # drive's position is this plant's elevation (J_az(el))
        self.unit_id = unit_id
        self.neighbours = dict(neighbours or {})
        self.held_drives: dict[str, ModbusEmulator] = {}  # the same drives, by axis name
        self._elevation_of = elevation_of
        self.clamp_output_bit = clamp_output_bit  # the bench's clamp, on this output
        self.shaft_torque_nm = 0.0  # what a shaft torque transducer reads (clamped)
        self._put("firmware_version", version_code(self.firmware.version))
        self._put("serial_number", serial_number)
        self._put("rated_torque", rated_torque_nm)
        self._put("mode", self.map.modes["velocity"])
        self._sample(self._hold_trace())

    # -- life cycle ----------------------------------------------------------------------
    def start(self) -> None:
        self._thread = threading.Thread(
            target=self._serve_forever, name="modbus-emulator", daemon=True
        )
        self._thread.start()
        if not self._ready.wait(10):
            raise RuntimeError("Modbus emulator did not start")
        log.info("Modbus emulator (%s) on 127.0.0.1:%d", self.framing, self.port)

    def _serve_forever(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        loop.run_until_complete(self._main())
        loop.close()

    async def _main(self) -> None:
        if self.unit_id is None:
            context = ModbusServerContext(devices=_Context(self), single=True)  # type: ignore[no-untyped-call]
        else:
            devices = {self.unit_id: _Context(self),
                       **{unit: _Context(other) for unit, other in self.neighbours.items()}}
            context = ModbusServerContext(devices=devices, single=False)  # type: ignore[no-untyped-call]
        framer = FramerType.RTU if self.framing == "rtu" else FramerType.SOCKET
        server = ModbusTcpServer(context, framer=framer, address=("127.0.0.1", 0))
        self._server = server
        await server.serve_forever(background=True)
        self.port = int(getattr(server.transport, "sockets")[0].getsockname()[1])  # noqa: B009
        self._ready.set()
        self._tick = time.monotonic()
        while not self._stopping:
            await asyncio.sleep(TICK_S)
            for drive in (self, *self.neighbours.values()):
                with drive._lock:
                    drive._credit_own_stall()
                    drive._advance()
                    drive._watchdog()
        await server.shutdown()  # type: ignore[no-untyped-call]

    def stop(self) -> None:
        self._stopping = True
        if self._thread is not None:
            self._thread.join(10)
        self._thread = None

    def __enter__(self) -> ModbusEmulator:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- requests ------------------------------------------------------------------------
    async def serve(
        self, func_code: int, address: int, count: int, values: list[int] | None
    ) -> Any:
        f = self.faults
        if f.response_delay_s:
            await asyncio.sleep(f.response_delay_s)
        with self._lock:
            self._advance()
            self._last_request = time.monotonic()
            self.requests += 1
            elapsed = self.time_enabled_s
            if f.drop_connection_after_s is not None and elapsed >= f.drop_connection_after_s:
                self._dropped = True
            if self._dropped:
                self._drop_connections()
                return ExcCodes.DEVICE_FAILURE  # never arrives: the connection is gone
            if f.stop_answering_after_s is not None and elapsed >= f.stop_answering_after_s:
                stall = True
            else:
                stall = False
                if f.exception_after_s is not None and elapsed >= f.exception_after_s:
                    return ExcCodes(f.exception_code)
                if address < 0 or address + count > len(self.regs):
                    return ExcCodes.ILLEGAL_ADDRESS
                if values is None:
                    if count > self.map.max_registers_per_read:
                        return ExcCodes.ILLEGAL_VALUE
                    if self.recorder is not None:
                        self.recorder.before_read(address, count)
                    words = [int(v) & 0xFFFF for v in self.regs[address : address + count]]
                    self._restart_torque_mean(address, count)
                    return words
                return self._write(address, values)
        if stall:
            await asyncio.sleep(3600)
        return None

    def _drop_connections(self) -> None:
        if self._server is None:
            return
        for connection in list(self._server.active_connections.values()):
            transport = getattr(connection, "transport", None)
            if transport is not None:
                transport.close()

    def _write(self, address: int, values: list[int]) -> ExcCodes | None:
        recorder = self.recorder
        if recorder is not None and recorder.refuses_write(address, len(values)):
            return ExcCodes.DEVICE_BUSY
        for offset, value in enumerate(values):
            self.regs[address + offset] = value
        outputs = self.map.registers.get(DIGITAL_OUTPUTS)
        if (outputs is not None and self.clamp_output_bit is not None
                and address <= outputs.address < address + len(values)):
            clamped = int(self._get(DIGITAL_OUTPUTS)) >> self.clamp_output_bit & 1
            self.plant.set_locked_rotor(bool(clamped))
        if self.map.has_compensation:
            start, span = self.map.compensation_span()
            if address < start + span and start < address + len(values):
                self._load_compensation()
        control = self.map["control_word"]
        if address <= control.address < address + len(values):
            self._apply_control(int(self._get("control_word")))
        name = self._mode_name()
        command = self.map[f"{name}_cmd"]
        if address < command.address + command.count and command.address < address + len(values):
            self._retarget(name)
        self._recorder_check()
        if recorder is not None and not recorder.written(
                address, len(values), mode=name,
                can_play=self.enabled and not self.quick_stopping and not self.fault_code):
            return ExcCodes.ILLEGAL_VALUE
        return None

    def _load_compensation(self) -> None:
        """The compensation table's registers into the drive: each slot with an order a
        harmonic (the plant applies them when its firmware has cogging compensation)."""
        tables = []
        for order_name, amplitude_name, phase_name in COMPENSATION.values():
            columns = []
            for name in (order_name, amplitude_name, phase_name):
                register = self.map[name]
                words = [int(w) & 0xFFFF for w in
                         self.regs[register.address : register.address + register.words]]
                columns.append(register.decode_raw(words) * register.scale)
            tables.append(tuple(Harmonic(order=round(o), amplitude=float(a), phase_rad=float(p))
                                for o, a, p in zip(*columns, strict=True) if round(o) > 0))
        self.plant.load_compensation(*tables)

    def _recorder_check(self) -> None:
        """A recorder playing stops when the drive stops (quick stop, disable, fault) or the
        host changes the mode."""
        recorder = self.recorder
        if recorder is None or not recorder.busy:
            return
        if (not self.enabled or self.quick_stopping or self.fault_code
                or self._mode_name() != recorder.mode):
            recorder.abort()

    def _recorder_ended(self) -> None:
        """After the table: the setpoint ramps from its last value to the mode's register
        over the setpoint interpolation time."""
        assert self.recorder is not None
        mode = self.recorder.mode
        steps = 0
        if SETPOINT_INTERPOLATION in self.map.registers:
            steps = round(self._get(SETPOINT_INTERPOLATION) * self.fs_hz)
        last = self.recorder.last_value() * self.map[f"{mode}_cmd"].scale
        self._setpoint = _Setpoint(mode=mode, start=last, target=self._get(f"{mode}_cmd"),
                                   begin=self._step(), steps=steps)

    def _mode_name(self) -> str:
        modes = {v: k for k, v in self.map.modes.items()}
        return modes.get(int(self._get("mode")), "velocity")

    def _step(self) -> int:
        """Index of the plant's next control period."""
        return round(self.plant.time_s * self.fs_hz)

    def _retarget(self, mode: str) -> None:
        """A new setpoint for the active mode: ramp to it from the one in effect now."""
        target = self._get(f"{mode}_cmd")
        step = self._step()
        steps = 0
        if SETPOINT_INTERPOLATION in self.map.registers:
            steps = round(self._get(SETPOINT_INTERPOLATION) * self.fs_hz)
        if self._setpoint.mode == mode and self.enabled and not self.quick_stopping:
            start = float(self._setpoint.values(step - 1, 1)[0])
        else:
            start = target
        self._setpoint = _Setpoint(mode=mode, start=start, target=target, begin=step, steps=steps)

    def _apply_control(self, word: int) -> None:
        bits = self.map.control_bits
        rising = word & ~self._control
        self._control = word
        if rising & (1 << bits["fault_reset"]) and self.fault_code:
            self.fault_code = 0
        if self.fault_code:
            self.enabled = False
            return
        if word & (1 << bits["quick_stop"]):
            if self.enabled and not self.quick_stopping:
                self.quick_stopping = True
                self._ramp = self.plant.velocity_rad_s
            return
        want = bool(word & (1 << bits["enable"]))
        if want and not self.enabled:
            self.plant.hold()
            self.quick_stopping = False
            self._setpoint = _Setpoint()  # a fresh enable starts from the register, no ramp
        self.enabled = want

    # -- registers -----------------------------------------------------------------------
    def _put(self, name: str, value: float) -> None:
        register = self.map[name] if name in self.map.registers else None
        if register is None:
            return
        words = register.encode(value)
        self.regs[register.address : register.address + register.count] = words

    def _get(self, name: str) -> float:
        register = self.map[name]
        words = [
            int(w) & 0xFFFF for w in self.regs[register.address : register.address + register.count]
        ]
        return register.decode(words)

    def _status_word(self) -> int:
        bits = self.map.status_bits
        word = 0
        if self.enabled and not self.quick_stopping:
            word |= 1 << bits["enabled"]
        if self.fault_code:
            word |= 1 << bits["fault"]
        if self.quick_stopping:
            word |= 1 << bits["quick_stop_active"]
        return word

    # -- the plant, in real time -------------------------------------------------------------
    def _advance(self) -> None:
        now = time.monotonic()
        steps = int((now - self._clock) * self.fs_hz)
        while steps > 0:
            block = min(steps, int(self.fs_hz))
            self._recorder_check()
            playing = self.recorder is not None and self.recorder.busy
            if playing:  # a block ends where the table does
                assert self.recorder is not None
                block = min(block, self.recorder.periods_left())
            self._clock += block / self.fs_hz
            steps -= block
            self._follow_elevation()
            mode, command = self._command(block)
            offset = None
            if self.enabled and TORQUE_OFFSET in self.map.registers:
                offset = np.full(block, self._get(TORQUE_OFFSET))  # held until written again
            if playing and self.enabled and not self.quick_stopping:
                assert self.recorder is not None
                table = self.recorder.play_offset(block)  # the offset table, if it plays one
                if table is not None:
                    offset = table * self.map[RECORDER_OFFSET].scale
            trace = self.plant.run(mode, command, offset)
            if self.recorder is not None:
                if playing and self.recorder.capture(trace, self._raw):
                    self._recorder_ended()
                self.recorder.observe(np.asarray(trace.torque_nm))
            shaft = trace.load_torque_nm  # the transducer between the clamp and the shaft
            self.shaft_torque_nm = 0.0 if shaft is None else float(np.mean(shaft))
            if self.enabled:
                self.time_enabled_s += block / self.fs_hz
            self._sample(trace)
            after = self.faults.drive_fault_after_s
            if after is not None and self.enabled and self.time_enabled_s >= after:
                self._trip(self.faults.drive_fault_code)

    def _follow_elevation(self) -> None:
        if self._elevation_of is not None:
            self.plant.follow_elevation(self._elevation_of())

    def _command(self, steps: int) -> tuple[Mode, np.ndarray]:
        if self.enabled and self.quick_stopping:
            decel = QUICK_STOP_DECEL_RAD_S2 * steps / self.fs_hz
            self._ramp -= math.copysign(min(decel, abs(self._ramp)), self._ramp)
            if self._ramp == 0.0 and abs(self.plant.velocity_rad_s) < 1e-3:
                self.enabled = False
            return Mode.VELOCITY, np.full(steps, self._ramp)
        if not self.enabled:
            return Mode.TORQUE, np.zeros(steps)
        name = self._mode_name()
        if self.recorder is not None and self.recorder.busy:  # the table, in its units
            return Mode(name), self.recorder.play(steps) * self.map[f"{name}_cmd"].scale
        if self._setpoint.mode != name:  # mode changed: the register's setpoint, at once
            self._setpoint = _Setpoint(mode=name, start=0.0, target=self._get(f"{name}_cmd"))
        return Mode(name), self._setpoint.values(self._step(), steps)

    def _hold_trace(self) -> Any:
        return self.plant.run(Mode.TORQUE, np.zeros(1))

    def _sample(self, trace: Any) -> None:
        self._put("status_word", self._status_word())
        self._put("fault_code", self.fault_code)
        self._put("position", float(trace.position_rad[-1]))
        self._put("velocity", float(trace.velocity_rad_s[-1]))
        self._put(
            "torque",
            float(
                np.clip(trace.torque_nm[-1], -16 * self.rated_torque_nm, 16 * self.rated_torque_nm)
            ),
        )
        self._put("current", float(trace.current_a[-1]))
        if TORQUE_MEAN in self.map.registers:
            self._torque_sum += float(np.sum(trace.torque_nm))
            self._torque_periods += len(trace.torque_nm)
            limit = 16 * self.rated_torque_nm
            mean = self._torque_sum / self._torque_periods
            self._put(TORQUE_MEAN, float(np.clip(mean, -limit, limit)))
            if TORQUE_MEAN_WINDOW in self.map.registers:
                register = self.map[TORQUE_MEAN_WINDOW]
                raw = min(
                    round(self._torque_periods / self.fs_hz / register.scale), register.modulus - 1
                )
                self._put(TORQUE_MEAN_WINDOW, raw * register.scale)
        if TIMESTAMP in self.map.registers:
            # the drive's clock at the latched state, wrapping like the counter it is
            register = self.map[TIMESTAMP]
            raw = round(float(trace.time_s[-1]) / register.scale) % register.modulus
            self._put(TIMESTAMP, raw * register.scale)
        for name in FEEDBACK:
            if name not in self.map.registers:
                raise KeyError(name)

    @property
    def _raw(self) -> dict[str, Callable[[np.ndarray], np.ndarray]]:
        """Per captured column: SI values → the raw counts of its capture window (torque
        limited as the torque register is)."""
        limit = 16 * self.rated_torque_nm

        def raw(name: str, low: float = -math.inf, high: float = math.inf
                ) -> Callable[[np.ndarray], np.ndarray]:
            register = self.map[RECORDER_COLUMNS[name]]
            lo, hi = register.raw_range
            return lambda si: np.clip(
                np.round(np.clip(si, low, high) / register.scale), lo, hi).astype(np.int64)

        return {"position": raw("position"), "velocity": raw("velocity"),
                "torque": raw("torque", -limit, limit), "current": raw("current")}

    def _restart_torque_mean(self, address: int, count: int) -> None:
        """A read that includes ``torque_mean``'s first word restarts the average: the next
        latched sample's mean is over the control periods after the one this read returned.
        The registers keep the served mean until a control period has run (a second read
        within one period returns the same latched state). Call with the lock held."""
        if TORQUE_MEAN not in self.map.registers:
            return
        if address <= self.map[TORQUE_MEAN].address < address + count:
            self._torque_sum = 0.0
            self._torque_periods = 0

    def _trip(self, code: int) -> None:
        if not self.fault_code:
            log.info("Modbus emulator: drive fault 0x%04X", code)
        self.fault_code = code
        self.enabled = False
        self.quick_stopping = False
        self._recorder_check()
        self._put("status_word", self._status_word())
        self._put("fault_code", code)

    def _credit_own_stall(self) -> None:
        """Time the emulator did not run is not time the master was silent.

        The emulator lives in the master's process: when the machine is overloaded the
        whole process (both threads) can be descheduled for 0.4-1 s. A real drive keeps
        running and sees the master's requests as they come; this one wakes up with the
        master's request still unread in its socket and its clock 1 s on, and would trip
        0x8130 (seen at load average 5-13). The part of a tick's delay beyond ``STALL_S``
        is therefore not counted as silence. Call with the lock held."""
        now = time.monotonic()
        late = now - self._tick - TICK_S
        self._tick = now
        if late > STALL_S:
            self._last_request += late
            self.stalls += 1
            self.longest_stall_s = max(self.longest_stall_s, late)

    def _watchdog(self) -> None:
        if self.enabled and time.monotonic() - self._last_request > self.watchdog_s:
            self._trip(WATCHDOG_FAULT)
