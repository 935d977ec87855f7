"""The exception hierarchy. Infrastructure faults are exceptions; a tolerance miss is not."""

from __future__ import annotations

#: control characters an error message shows escaped, so that it stays one line
_ONE_LINE = {ord("\n"): "\\n", ord("\r"): "\\r", ord("\t"): "\\t", ord("\v"): "\\v",
             ord("\f"): "\\f", 0x1C: "\\x1c", 0x1D: "\\x1d", 0x1E: "\\x1e", 0x85: "\\x85",
             0x2028: "\\u2028", 0x2029: "\\u2029"}


class HilError(Exception):
    """Base of every error gimbal-hil raises on purpose."""


class InputError(HilError):
    """Bad user input (file, profile, option), located as precisely as possible."""

    def __init__(
        self,
        message: str,
        *,
        source: str | None = None,
        line: int | None = None,
        column: str | None = None,
    ) -> None:
        self.message = message
        self.source = source
        self.line = line
        self.column = column
        where = ", ".join(
            part
            for part in (
                source,
                f"line {line}" if line is not None else None,
                f"column '{column}'" if column is not None else None,
            )
            if part
        )
        text = f"{where}: {message}" if where else message
        # one line, whatever the input held (a key or a value with a line break in it)
        super().__init__(text.translate(_ONE_LINE))


class RecordingError(InputError):
    """A recording file violates the recording format."""


class ProfileError(InputError):
    """A unit or station profile is missing a key or holds an invalid value."""


class DriveError(HilError):
    """Any drive problem. Raised only after the drive was brought to a safe state.

    ``partial_recording`` holds what was measured before the problem, when anything was.
    """

    partial_recording: object | None = None


class DriveCommunicationError(DriveError):
    """Lost connection, timeout, or a malformed answer from the drive."""


class DriveFaultError(DriveError):
    """The drive reported a fault (EMCY code, Modbus exception, simulated trip)."""

    def __init__(self, message: str, *, code: int | None = None) -> None:
        self.code = code
        super().__init__(f"{message} (code 0x{code:04X})" if code is not None else message)


class DriveStateError(DriveError):
    """The drive is in a state that does not allow the request (not enabled, faulted, ...)."""


class LimitViolationError(DriveError):
    """A command would leave the unit's velocity, torque or travel limits (nothing moved), or
    the measured motion left them while moving (the axis quick-stopped; what was recorded
    up to then on ``partial_recording``)."""


class IdentificationError(HilError):
    """The data cannot support the requested fit (too short, ill-conditioned, saturated)."""
