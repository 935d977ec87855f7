"""CiA 402 servo drives over CANopen (``canopen`` + ``python-can``): the client
(``drive``, ``link``, ``acquire``) and, beside it, the drive emulator (``emulator``)."""
