"""The emulated Modbus drive's recorder: a waveform table it plays at its control rate, and
capture buffers it fills meanwhile (the register map's ``recorder_*`` registers).

The host writes the table through the waveform window (``recorder_index`` and the window in
one request), sets ``recorder_length`` and ``recorder_divider`` and writes 1 to
``recorder_control``; from the next control period on the drive plays table sample ``k``
over control periods ``k·n … k·n + n − 1`` (``n`` the divider) in the mode of its ``mode``
register, in that register's ``*_cmd`` units, and captures the plant's sample of control
period ``k·n`` (position at its start, the torque commanded over it, velocity and current)
as capture sample ``k``; with ``recorder_torque_sample`` = 1 the torque captured is the mean
of the torque commanded over control periods ``k·n − n + 1 … k·n`` (the ``torque_mean``
register's definition over the sample's ``n`` periods; ``n`` = 1: the period's own).
Triggered with 3 (where the map has ``recorder_offset``) it adds the offset table's sample
``k`` to its torque command over the same periods, as the ``torque_offset`` register would
be (a firmware with feedforward). A quick stop, a disable, a fault or a mode change while it
plays aborts it (state 3); what was captured stays readable. After the table the drive's setpoint
ramps from the table's last value to its ``*_cmd`` register over the setpoint
interpolation time (the host writes there what the axis should hold).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hil.drives.modbus.regmap import (
    RECORDER_ABORT,
    RECORDER_ABORTED,
    RECORDER_BUSY,
    RECORDER_CAPACITY,
    RECORDER_COLUMNS,
    RECORDER_CONTROL,
    RECORDER_DIVIDER,
    RECORDER_DONE,
    RECORDER_INDEX,
    RECORDER_LENGTH,
    RECORDER_OFFSET,
    RECORDER_SAMPLES,
    RECORDER_START,
    RECORDER_START_WITH_OFFSET,
    RECORDER_STATE,
    RECORDER_TORQUE_MEAN,
    RECORDER_TORQUE_SAMPLE,
    RECORDER_WAVEFORM,
    Register,
    RegisterMap,
)

CAPACITY = 16384  # samples, as the CANopen emulator's recorder
HISTORY = 1024  # control periods of torque kept from before a block (a mean's window)


class ModbusRecorder:
    """The recorder of one emulated drive (one per unit id). Its registers live in the
    emulator's register array ``regs``; call every method with the emulator's lock held.

    Parameters
    ----------
    register_map : RegisterMap
        A map that declares the recorder (:attr:`RegisterMap.has_recorder`).
    regs : numpy.ndarray
        The emulator's holding registers.
    capacity : int
        Samples the table and the buffers hold.
    """

    def __init__(self, register_map: RegisterMap, regs: np.ndarray, *,
                 capacity: int = CAPACITY) -> None:
        self.map = register_map
        self.regs = regs
        self.capacity = capacity
        self.state = 0
        self.mode = ""  # the mode it plays in (the mode register's at the trigger)
        self.table = np.zeros(capacity, dtype=np.int64)
        self.offsets = np.zeros(capacity, dtype=np.int64)  # the torque offset table
        self.with_offset = False  # this play adds the offset table
        self.mean = False  # this play captures the torque's mean over each sample
        self._recent = np.zeros(0)  # the torque of the control periods before a block
        self.captured = {name: np.zeros(capacity, dtype=np.int64) for name in RECORDER_COLUMNS}
        self.count = 0  # samples captured
        self.length = 0  # samples to play
        self.divider = 1
        self._period = 0  # control periods played
        self._put(RECORDER_CAPACITY, capacity)
        self._put(RECORDER_DIVIDER, 1)
        self._publish()

    # -- registers -----------------------------------------------------------------------
    def _register(self, name: str) -> Register:
        return self.map[name]

    def _put(self, name: str, raw: int) -> None:
        register = self._register(name)
        self.regs[register.address : register.address + register.count] = register.encode(
            raw * register.scale)

    def _get(self, name: str) -> int:
        register = self._register(name)
        words = [int(w) & 0xFFFF for w in self.regs[register.address : register.address
                                                     + register.count]]
        return round(register.decode(words) / register.scale)

    def _publish(self) -> None:
        self._put(RECORDER_STATE, self.state)
        self._put(RECORDER_SAMPLES, self.count)

    @staticmethod
    def _overlaps(register: Register, address: int, count: int) -> bool:
        return address < register.address + register.words and register.address < address + count

    @property
    def busy(self) -> bool:
        return self.state == RECORDER_BUSY

    # -- requests ------------------------------------------------------------------------
    def refuses_write(self, address: int, count: int) -> bool:
        """A write the drive refuses (SERVER DEVICE BUSY): the table, its length or
        divider while playing."""
        return self.busy and any(
            self._overlaps(self._register(name), address, count)
            for name in (RECORDER_WAVEFORM, RECORDER_LENGTH, RECORDER_DIVIDER))

    def written(self, address: int, count: int, *, mode: str, can_play: bool) -> bool:
        """After a write of registers ``address … address + count − 1``: the table window
        stored, a trigger or an abort carried out. ``False``: the trigger is refused
        (ILLEGAL DATA VALUE: the drive not enabled, or an empty, too long or ill-divided
        table); the recorder is then idle."""
        self._store(RECORDER_WAVEFORM, self.table, address, count)
        if RECORDER_OFFSET in self.map.registers:
            self._store(RECORDER_OFFSET, self.offsets, address, count)
        if not self._overlaps(self._register(RECORDER_CONTROL), address, count):
            return True
        command = self._get(RECORDER_CONTROL)
        starts = (RECORDER_START, *((RECORDER_START_WITH_OFFSET,)
                                    if RECORDER_OFFSET in self.map.registers else ()))
        if command == RECORDER_ABORT:
            self.abort()
        elif command in starts:
            length, divider = self._get(RECORDER_LENGTH), self._get(RECORDER_DIVIDER)
            if not can_play or not 1 <= length <= self.capacity or divider < 1 or self.busy:
                self._put(RECORDER_CONTROL, 0)
                return False
            self.length, self.divider, self.mode = length, divider, mode
            self.with_offset = command == RECORDER_START_WITH_OFFSET
            self.mean = (RECORDER_TORQUE_SAMPLE in self.map.registers
                         and self._get(RECORDER_TORQUE_SAMPLE) == RECORDER_TORQUE_MEAN)
            self.count, self._period = 0, 0
            self.state = RECORDER_BUSY
        self._put(RECORDER_CONTROL, 0)
        self._publish()
        return True

    def _store(self, name: str, table: np.ndarray, address: int, count: int) -> None:
        """The values a write put into the window ``name`` go into ``table`` from
        ``recorder_index`` on."""
        window = self._register(name)
        if not self._overlaps(window, address, count):
            return
        index = self._get(RECORDER_INDEX)
        first = max(address, window.address)
        last = min(address + count, window.address + window.words)
        for slot in range((first - window.address) // window.count,
                          -(-(last - window.address) // window.count)):
            at = window.address + slot * window.count
            if index + slot < self.capacity:
                words = [int(w) & 0xFFFF for w in self.regs[at : at + window.count]]
                table[index + slot] = round(window.decode(words) / window.scale)

    def before_read(self, address: int, count: int) -> None:
        """Fill the capture windows from ``recorder_index`` if the read includes them."""
        index = self._get(RECORDER_INDEX)
        for name, register_name in RECORDER_COLUMNS.items():
            register = self._register(register_name)
            if not self._overlaps(register, address, count):
                continue
            values = np.zeros(register.length, dtype=np.int64)
            have = max(0, min(register.length, self.count - index))
            values[:have] = self.captured[name][index : index + have]
            self.regs[register.address : register.address + register.words] = \
                register.encode_raw(values)

    # -- playing -------------------------------------------------------------------------
    def periods_left(self) -> int:
        """Control periods of the table still to play (0: not playing)."""
        return self.length * self.divider - self._period if self.busy else 0

    def play(self, steps: int) -> np.ndarray:
        """The table's raw values over the next ``steps`` control periods (at most
        :meth:`periods_left`)."""
        periods = self._period + np.arange(steps)
        return self.table[periods // self.divider].astype(np.float64)

    def play_offset(self, steps: int) -> np.ndarray | None:
        """The offset table's raw values over the next ``steps`` control periods, or
        ``None`` when this play has none."""
        if not self.with_offset:
            return None
        periods = self._period + np.arange(steps)
        return self.offsets[periods // self.divider].astype(np.float64)

    def observe(self, torque_nm: np.ndarray) -> None:
        """The torque commanded over a block of control periods (every block, playing or
        not: a mean's window reaches back before the play)."""
        self._recent = np.concatenate([self._recent, torque_nm])[-HISTORY:]

    def _torque_means(self, torque_nm: np.ndarray, keep: np.ndarray) -> np.ndarray:
        """Per captured period ``keep`` of a block: the mean of the torque over the
        ``divider`` periods up to and including it (those before the block from
        :meth:`observe`)."""
        full = np.concatenate([self._recent, torque_nm])
        sums = np.concatenate([[0.0], np.cumsum(full)])
        ends = keep + len(self._recent) + 1
        starts = np.maximum(ends - self.divider, 0)
        means: np.ndarray = (sums[ends] - sums[starts]) / (ends - starts)
        return means

    def capture(self, trace: Any, raw: dict[str, Any]) -> bool:
        """Capture the samples of ``trace`` (the control periods :meth:`play` gave), their
        raw values by ``raw[column](si values)``; ``True`` when the table has ended. Call
        before :meth:`observe` of the same block."""
        n = len(trace.time_s)
        periods = self._period + np.arange(n)
        keep = np.flatnonzero(periods % self.divider == 0)
        rows = periods[keep] // self.divider
        torque = np.asarray(trace.torque_nm)
        si = {"position": trace.position_rad, "velocity": trace.velocity_rad_s,
              "torque": torque, "current": trace.current_a}
        if self.mean and self.divider > 1:
            si["torque"] = np.zeros(n)
            si["torque"][keep] = self._torque_means(torque, keep)
        for name in RECORDER_COLUMNS:
            self.captured[name][rows] = raw[name](np.asarray(si[name])[keep])
        self.count += len(rows)
        self._period += n
        if self._period >= self.length * self.divider:
            self.state = RECORDER_DONE
        self._publish()
        return self.state == RECORDER_DONE

    def last_value(self) -> float:
        """The table's last raw value."""
        return float(self.table[max(self.length - 1, 0)])

    def abort(self) -> None:
        """Stop playing (a quick stop, a disable, a fault, the host): what was captured
        stays."""
        if self.busy:
            self.state = RECORDER_ABORTED
            self._publish()
