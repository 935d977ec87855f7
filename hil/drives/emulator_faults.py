"""Fault injection settings of the protocol-level emulators (all off by default)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True, kw_only=True)
class CanFaults:
    """Faults the CANopen emulator can inject.

    Times are plant seconds spent in OPERATION ENABLED (the emulator's clock is the SYNC),
    so a fault lands at the same point of an excitation however loaded the machine is.
    """

    drop_tpdo_every: int = 0  # drop every n-th transmitted TPDO frame (0: none)
    drop_all_tpdo_after_s: float | None = None  # stop sending TPDOs altogether
    sdo_delay_s: float = 0.0  # answer every SDO request this late
    emcy_after_s: float | None = None  # enter FAULT and send EMCY
    emcy_code: int = 0x2310  # CiA 402: continuous over-current
    fault_persists: bool = False  # a fault reset does not clear the fault
    bus_error_after_s: float | None = None  # the master's CAN controller reports an error


@dataclass(frozen=True, slots=True, kw_only=True)
class ModbusFaults:
    """Faults the Modbus emulator can inject (times in seconds since the drive was enabled)."""

    response_delay_s: float = 0.0  # line delay added to every answer
    exception_after_s: float | None = None  # answer every request with an exception
    exception_code: int = 4  # SERVER DEVICE FAILURE
    drive_fault_after_s: float | None = None  # the drive trips (fault bit + fault code)
    drive_fault_code: int = 0x2310
    drop_connection_after_s: float | None = None  # close the connection, refuse service
    stop_answering_after_s: float | None = None  # swallow requests (client times out)
