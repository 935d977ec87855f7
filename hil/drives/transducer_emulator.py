"""An emulated torque transducer amplifier: a pymodbus server on 127.0.0.1 whose input
registers ``address``, ``address + 1`` hold the shaft torque (float32, N·m, high word
first) an emulated drive's plant reports at the moment of the request."""

from __future__ import annotations

import asyncio
import struct
import threading
from collections.abc import Callable
from typing import Any

from pymodbus import FramerType
from pymodbus.datastore import ModbusServerContext
from pymodbus.datastore.context import ModbusBaseDeviceContext
from pymodbus.server import ModbusTcpServer

READ_INPUT_REGISTERS = 4


class _Amplifier(ModbusBaseDeviceContext):  # type: ignore[misc]
    def __init__(self, emulator: TransducerEmulator) -> None:
        self.emulator = emulator

    def reset(self) -> None:  # pragma: no cover - required by the interface
        pass

    async def async_getValues(self, func_code: int, address: int, count: int = 1) -> Any:  # noqa: N802
        return self.emulator.registers(func_code, address, count)

    async def async_setValues(self, func_code: int, address: int,  # noqa: N802
                              values: list[int] | list[bool]) -> Any:
        return None  # read-only: the write is ignored, as the amplifier's own would be


class TransducerEmulator:
    """The amplifier of a shaft torque transducer reading ``shaft_torque_nm()``."""

    def __init__(self, shaft_torque_nm: Callable[[], float], *, address: int = 0) -> None:
        self.shaft_torque_nm = shaft_torque_nm
        self.address = address
        self.port = 0
        self.reads = 0
        self._ready = threading.Event()
        self._stopping = False
        self._thread: threading.Thread | None = None

    def registers(self, func_code: int, address: int, count: int) -> list[int]:
        """The words a request reads (zeros outside the torque's two registers)."""
        words = [0] * count
        if func_code != READ_INPUT_REGISTERS:
            return words
        high, low = struct.unpack(">HH", struct.pack(">f", self.shaft_torque_nm()))
        for i in range(count):
            words[i] = {self.address: high, self.address + 1: low}.get(address + i, 0)
        self.reads += 1
        return words

    def start(self) -> None:
        self._thread = threading.Thread(target=lambda: asyncio.run(self._main()),
                                        name="transducer-emulator", daemon=True)
        self._thread.start()
        if not self._ready.wait(10):
            raise RuntimeError("transducer emulator did not start")

    async def _main(self) -> None:
        context = ModbusServerContext(devices=_Amplifier(self), single=True)  # type: ignore[no-untyped-call]
        server = ModbusTcpServer(context, framer=FramerType.SOCKET, address=("127.0.0.1", 0))
        await server.serve_forever(background=True)
        self.port = int(getattr(server.transport, "sockets")[0].getsockname()[1])  # noqa: B009
        self._ready.set()
        while not self._stopping:
            await asyncio.sleep(0.02)
        await server.shutdown()  # type: ignore[no-untyped-call]

    def stop(self) -> None:
        self._stopping = True
        if self._thread is not None:
            self._thread.join(10)
        self._thread = None

    def __enter__(self) -> TransducerEmulator:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
