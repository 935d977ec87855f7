"""CiA 402 servo drives over CANopen (``canopen`` + ``python-can``)."""

from hil.drives.cia402.drive import CanOpenDrive

__all__ = ["CanOpenDrive"]
