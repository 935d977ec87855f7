"""Drives over Modbus TCP / RTU (``pymodbus``, serial ports and URLs via ``pyserial``)."""

from hil.drives.modbus.drive import ModbusDrive

__all__ = ["ModbusDrive"]
