"""gimbal-hil: hardware-in-the-loop calibration of gimbal servo axes."""


def __getattr__(name: str) -> str:
    """``__version__``, read from the installed metadata when first asked for (importing
    ``importlib.metadata`` costs 50-60 ms of every command's start, ``--help`` included)."""
    if name != "__version__":
        raise AttributeError(f"module 'hil' has no attribute {name!r}")
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("gimbal-hil")
    except PackageNotFoundError:  # running from a source tree that is not installed
        return "0.0.0+unknown"


__all__ = ["__version__"]
