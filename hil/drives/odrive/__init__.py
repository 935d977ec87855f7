"""ODrive over CANSimple: protocol, link, acquisition, axis state machine, drive, emulator."""
