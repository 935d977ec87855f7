"""Reading a shaft torque transducer's amplifier over Modbus TCP while the drive runs, and
putting its readings on a recording's rows.

Each reading is stamped with the drive's clock as the backend gives it (a CANopen drive:
the SYNCs since the run began; a polled drive: its own time), so that it lands on the row
it belongs to whatever the host's pace. On a real bus the amplifier is polled on a thread
of its own (:meth:`TransducerReader.start`); against an emulator in lockstep, whose clock
runs as fast as the host lets it, the backend reads it once per step instead
(:meth:`TransducerReader.read_in_step`). The readings are interpolated onto the rows; the
torque-constant protocol averages the shaft torque over levels held for many rows.
"""

from __future__ import annotations

import struct
import threading
from collections.abc import Callable

import numpy as np
from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusException

from hil.drives.equipment import TorqueTransducer
from hil.errors import DriveCommunicationError
from hil.recording import Recording

MIN_READINGS = 4  # fewer over a run: the transducer did not answer often enough


class TransducerReader:
    """The transducer's readings (N·m, zero subtracted) while :meth:`polling`."""

    def __init__(self, transducer: TorqueTransducer) -> None:
        self.transducer = transducer
        self._client = ModbusTcpClient(transducer.host, port=transducer.port, timeout=0.5,
                                       retries=0)
        self._times_s: list[float] = []
        self._values_nm: list[float] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._error: DriveCommunicationError | None = None
        self._clock_s: Callable[[], float] = lambda: 0.0

    def open(self) -> None:
        """Connect and take one reading.

        Raises
        ------
        DriveCommunicationError
            The amplifier does not answer, or answers with an error.
        """
        if not self._client.connect():  # type: ignore[no-untyped-call]
            raise DriveCommunicationError(f"{self.transducer.where}: cannot connect")
        self.read_nm()

    def close(self) -> None:
        self.stop()
        self._client.close()  # type: ignore[no-untyped-call]

    def read_nm(self) -> float:
        """One reading (N·m).

        Raises
        ------
        DriveCommunicationError
            No answer, or a Modbus exception.
        """
        t = self.transducer
        try:
            response = self._client.read_input_registers(t.address, count=2,
                                                         device_id=t.unit_id)
        except (ModbusException, OSError) as exc:
            raise DriveCommunicationError(f"{t.where}: {exc}") from exc
        if response.isError():
            raise DriveCommunicationError(f"{t.where}: answered {response}")
        high, low = response.registers
        (value,) = struct.unpack(">f", struct.pack(">HH", high, low))
        return float(value) * t.scale_nm - t.zero_nm

    def begin(self, clock_s: Callable[[], float]) -> None:
        """A new run, its rows timed by ``clock_s`` (the readings of an earlier one
        forgotten)."""
        self._clock_s = clock_s
        self._times_s, self._values_nm, self._error = [], [], None

    def read_in_step(self) -> None:
        """One reading, stamped now (the backend calls it once per step of its clock)."""
        if self._error is None:
            try:
                self._values_nm.append(self.read_nm())
                self._times_s.append(self._clock_s())
            except DriveCommunicationError as exc:
                self._error = exc

    def start(self, clock_s: Callable[[], float]) -> None:
        """Begin polling on a thread, each reading stamped by ``clock_s``."""
        self.begin(clock_s)
        self._stop.clear()
        self._thread = threading.Thread(target=self._poll, name="torque-transducer",
                                         daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None

    def _poll(self) -> None:
        period = self.transducer.poll_period_s
        while not self._stop.is_set():
            try:
                value = self.read_nm()
            except DriveCommunicationError as exc:
                self._error = exc
                return
            self._times_s.append(self._clock_s())
            self._values_nm.append(value)
            self._stop.wait(period)

    def on_rows(self, recording: Recording) -> Recording:
        """``recording`` with this run's readings, interpolated onto its rows by their
        stamps, as ``load_torque_nm``.

        Raises
        ------
        DriveCommunicationError
            The transducer stopped answering, or gave fewer than :data:`MIN_READINGS`.
        """
        self.stop()
        if self._error is not None:
            raise self._error
        if len(self._values_nm) < MIN_READINGS or len(recording) < 2:
            raise DriveCommunicationError(
                f"{self.transducer.where}: {len(self._values_nm)} readings over the run "
                f"(at least {MIN_READINGS} needed)")
        shaft = np.interp(recording.time_s, np.asarray(self._times_s),
                          np.asarray(self._values_nm))
        columns = {**recording.columns, "load_torque_nm": shaft}
        metadata = {**recording.metadata,
                    "shaft_torque": f"{self.transducer.where}, certificate "
                                    f"{self.transducer.certificate}, "
                                    f"{len(self._values_nm)} readings placed by the drive's "
                                    "clock"}
        return Recording(columns=columns, metadata=metadata, source=recording.source)
