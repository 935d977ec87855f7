"""The Modbus link of one drive: client (TCP or RTU), requests with the drive's exception
codes turned into errors, a resend after a TCP timeout, and register values in SI units.

It knows the register map but nothing of the CiA-style state machine or of acquisition.
"""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from typing import Any

from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ModbusException
from pymodbus.framer import FramerType

from hil.drives.modbus.regmap import RegisterMap
from hil.drives.station import ModbusStation
from hil.errors import DriveCommunicationError, DriveFaultError

EXCEPTION_NAMES = {
    1: "ILLEGAL FUNCTION",
    2: "ILLEGAL DATA ADDRESS",
    3: "ILLEGAL DATA VALUE",
    4: "SERVER DEVICE FAILURE",
    5: "ACKNOWLEDGE",
    6: "SERVER DEVICE BUSY",
    0x0A: "GATEWAY PATH UNAVAILABLE",
    0x0B: "GATEWAY TARGET FAILED TO RESPOND",
}


class ModbusLink:
    """Requests to one Modbus unit.

    Parameters
    ----------
    station : ModbusStation
        Transport, address, unit id and timeouts.
    register_map : RegisterMap
        Where each value lives and how it is coded.

    Raises
    ------
    DriveCommunicationError
        The connection cannot be made (:meth:`connect`) or a request fails or times out.
    DriveFaultError
        The drive answers a request with a Modbus exception (its code attached).
    """

    def __init__(self, station: ModbusStation, register_map: RegisterMap, *,
                 client: Any = None, lock: threading.Lock | None = None) -> None:
        self.station = station
        self.map = register_map
        self._client = client if client is not None else self._make_client()
        # one request at a time on the connection (the idle keepalive's thread shares it)
        self._lock = lock if lock is not None else threading.Lock()
        self.last_request_s = time.monotonic()  # when this unit was last sent a request

    def for_unit(self, unit_id: int) -> ModbusLink:
        """The drive at ``unit_id`` on the same connection (a gimbal's other axis on this
        line or server; the same register map)."""
        return ModbusLink(replace(self.station, unit_id=unit_id), self.map, client=self._client,
                          lock=self._lock)

    def _make_client(self) -> Any:
        st = self.station
        if st.transport == "tcp":
            # one resend after a timeout: an overloaded host can be descheduled for longer
            # than timeout_s while the answer is under way; the resend keeps the
            # transaction id, so whichever answer comes first is matched, the other skipped.
            # RTU has no transaction id (a late answer would be taken for the next
            # request's), so it is not resent there.
            return ModbusTcpClient(st.host, port=st.port, timeout=st.timeout_s, retries=1)
        return ModbusSerialClient(
            st.serial_port,
            framer=FramerType.RTU,
            baudrate=st.baudrate,
            parity=st.parity,
            stopbits=st.stopbits,
            timeout=st.timeout_s,
            retries=0,
        )

    @property
    def where(self) -> str:
        """``modbus tcp HOST:PORT unit N`` (or the serial port): for every message."""
        st = self.station
        link = f"{st.host}:{st.port}" if st.transport == "tcp" else st.serial_port
        return f"modbus {st.transport} {link} unit {st.unit_id}"

    @property
    def connected(self) -> bool:
        return bool(self._client.connected)

    def connect(self) -> None:
        """(Re)open the connection."""
        if not self._client.connect():
            raise DriveCommunicationError(f"{self.where}: cannot connect")

    def close(self) -> None:
        self._client.close()

    def _call(self, what: str, method: str, *args: Any, **kwargs: Any) -> Any:
        gap = self.map.frame_gap_s
        if gap:
            time.sleep(gap)
        try:
            with self._lock:
                self.last_request_s = time.monotonic()
                response = getattr(self._client, method)(
                    *args, device_id=self.station.unit_id, **kwargs
                )
        except ModbusException as exc:
            raise DriveCommunicationError(f"{self.where}: {what}: {exc}") from exc
        except OSError as exc:
            raise DriveCommunicationError(f"{self.where}: {what}: {exc}") from exc
        if response.isError():
            code = int(getattr(response, "exception_code", 0))
            name = EXCEPTION_NAMES.get(code, "unknown")
            raise DriveFaultError(
                f"{self.where}: {what} answered with Modbus exception {code} ({name})",
                code=code,
            )
        return response

    def read_words(self, blocks: list[tuple[int, int]]) -> dict[int, int]:
        """The registers of ``blocks`` (``(address, count)``, one request each), by address."""
        words: dict[int, int] = {}
        for address, count in blocks:
            response = self._call(
                f"read {count} registers at {address}",
                "read_holding_registers",
                address,
                count=count,
            )
            for offset, value in enumerate(response.registers):
                words[address + offset] = value
        return words

    def decode(self, words: dict[int, int], names: tuple[str, ...]) -> dict[str, float]:
        """The SI values of ``names`` (those the map has) from words read."""
        out = {}
        for name in names:
            if name in self.map.registers:
                r = self.map[name]
                out[name] = r.decode([words[r.address + i] for i in range(r.count)])
        return out

    def read_values(self, names: tuple[str, ...]) -> dict[str, float]:
        """Read ``names`` (in as few requests as the map allows) in SI units."""
        return self.decode(self.read_words(self.map.blocks(names)), names)

    def write_words(self, address: int, words: list[int], what: str) -> None:
        """Write registers from ``address`` on in one request."""
        self._call(f"write {what}", "write_registers", address, words)

    def write_value(self, name: str, value_si: float) -> None:
        """Write one register from an SI value."""
        register = self.map[name]
        self._call(f"write {name}", "write_registers", register.address, register.encode(value_si))
