"""Drives over Modbus TCP / RTU (``pymodbus``, serial ports and URLs via ``pyserial``): the
client (``drive``) and, beside it, the drive emulator (``emulator``)."""
