"""The drive kinds ``--drive`` accepts (kept import-light: the pytest entry point reads it)."""

DRIVE_KINDS = ("sim", "canopen-emulator", "modbus-emulator", "canopen", "modbus")
SIMULATED_KINDS = ("sim", "canopen-emulator", "modbus-emulator")  # need no --unit-serial
