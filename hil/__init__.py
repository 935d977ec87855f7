"""gimbal-hil: hardware-in-the-loop calibration of gimbal servo axes."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("gimbal-hil")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
