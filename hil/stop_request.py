"""A stop asked for by a signal, kept for the rest of the run.

The calibration's signal handler raises ``KeyboardInterrupt`` wherever the main thread is.
Python drops an exception raised inside a finaliser (an object's ``__del__``, a weakref
callback: "Exception ignored in …" on stderr), so a stop landing there would be lost and the
run would go on to its end and pass. The request is therefore also kept here: no motion and
no protocol starts after it, and the certificate says aborted.
"""

from __future__ import annotations


class StopRequest:
    """The first stop signal of a run, by name (``None`` while none has come)."""

    def __init__(self) -> None:
        self.signal_name: str | None = None

    @property
    def asked(self) -> bool:
        return self.signal_name is not None

    def ask(self, signal_name: str) -> None:
        """Keep the first stop; a later one changes nothing."""
        if self.signal_name is None:
            self.signal_name = signal_name

    def honour(self, what: str) -> None:
        """Raise ``KeyboardInterrupt`` when a stop was asked for, so ``what`` (a motion, a
        protocol) does not start."""
        if self.signal_name is not None:
            raise KeyboardInterrupt(
                f"{self.signal_name}: the calibration stops ({what} not started)")
