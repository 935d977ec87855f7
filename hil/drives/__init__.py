"""Drive backends behind one contract (:mod:`hil.drives.base`).

``connect.open_drive`` opens one by kind; ``sim`` drives the plant in-process, ``cia402``
and ``modbus`` each hold a client and, beside it, the emulator of the drive it talks to.
"""
