"""The emulated drive's waveform table (0x2100) and trace recorder (0x2200).

Real servo drives carry a function generator and a recorder that samples at the control
loop rate, far above what a fieldbus can stream; the master downloads the waveform,
starts it, and uploads the trace afterwards by segmented SDO. Sample layout in 0x2200:7
(little endian, 12 bytes): position (int32, increments), velocity (int32, the drive's
velocity units), torque (int16, per-mille of rated), current (int16, per-mille of rated).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from canopen.sdo.exceptions import SdoAbortedError

from plant_sim.model import PlantTrace

IDLE, RUNNING, DONE, ABORTED = 0, 1, 2, 3
SAMPLE = np.dtype([("pos", "<i4"), ("vel", "<i4"), ("torque", "<i2"), ("current", "<i2")])


class DriveRecorder:
    def __init__(
        self,
        *,
        capacity: int,
        loop_period_us: int,
        counts_per_rad: float,
        velocity_per_rad_s: float,
        rated_torque_nm: float,
        rated_current_a: float,
    ) -> None:
        self.capacity = capacity
        self.loop_period_us = loop_period_us
        self._counts_per_rad = counts_per_rad
        self._velocity_per_rad_s = velocity_per_rad_s
        self._torque_scale = 1e3 / rated_torque_nm
        self._current_scale = 1e3 / rated_current_a
        self.status = IDLE
        self.divider = 1
        self._waveform = np.zeros(0, dtype=np.int32)
        self._cursor = 0
        self._phase = 0
        self._chunks: list[np.ndarray] = []
        self._count = 0

    def read(self, index: int, subindex: int) -> Any:
        if index == 0x2100:
            return self._waveform.astype("<i4").tobytes() if subindex == 1 else len(self._waveform)
        return {
            1: self.status == RUNNING,
            2: self.status,
            3: self.divider,
            4: self._count,
            5: self.capacity,
            6: self.loop_period_us,
            7: self.data(),
        }.get(subindex)

    def data(self) -> bytes:
        if not self._chunks:
            return b""
        return b"".join(chunk.tobytes() for chunk in self._chunks)

    def write(self, index: int, subindex: int, value: Any, *, running: bool) -> None:
        if self.status == RUNNING:
            raise SdoAbortedError(0x08000022)  # not while recording
        if index == 0x2100 and subindex == 1:
            raw = bytes(value)
            if len(raw) % 4:
                raise SdoAbortedError(0x06070010)
            self._waveform = np.frombuffer(raw, dtype="<i4").astype(np.int32)
        elif index == 0x2200 and subindex == 3:
            if int(value) < 1:
                raise SdoAbortedError(0x06090030)
            self.divider = int(value)
        elif index == 0x2200 and subindex == 1 and int(value) == 1:
            needed = -(-len(self._waveform) // self.divider)
            if not running or not len(self._waveform) or needed > self.capacity:
                raise SdoAbortedError(0x08000022 if not running else 0x06090030)
            self._cursor, self._phase, self._count, self._chunks = 0, 0, 0, []
            self.status = RUNNING

    @property
    def last_target(self) -> int:
        """The waveform's last sample: where a position table leaves the axis."""
        return int(self._waveform[-1]) if len(self._waveform) else 0

    def waveform_block(self, steps: int) -> np.ndarray | None:
        """The next ``steps`` waveform samples while running (padded with the last one)."""
        if self.status != RUNNING:
            return None
        block = self._waveform[self._cursor : self._cursor + steps]
        if len(block) < steps:
            block = np.concatenate([block, np.full(steps - len(block), self._waveform[-1])])
        self._cursor += steps
        return block

    def capture(self, trace: PlantTrace, *, enabled: bool) -> None:
        if self.status != RUNNING:
            return
        if not enabled:
            self.status = ABORTED
            return
        n = len(trace.time_s)
        total = len(self._waveform)
        start = self._cursor - n  # waveform index of trace sample 0
        keep = [i for i in range(n) if start + i < total and (start + i) % self.divider == 0]
        if keep:
            idx = np.asarray(keep)
            chunk = np.empty(len(idx), dtype=SAMPLE)
            chunk["pos"] = np.round(trace.position_rad[idx] * self._counts_per_rad)
            chunk["vel"] = np.round(trace.velocity_rad_s[idx] * self._velocity_per_rad_s)
            chunk["torque"] = np.clip(
                np.round(trace.torque_nm[idx] * self._torque_scale), -32768, 32767
            )
            chunk["current"] = np.clip(
                np.round(trace.current_a[idx] * self._current_scale), -32768, 32767
            )
            self._chunks.append(chunk)
            self._count += len(idx)
        if self._cursor >= total:
            self.status = DONE
