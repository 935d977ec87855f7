"""The host's share of keeping time while an excitation runs."""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def collector_held() -> Iterator[None]:
    """Python's cyclic garbage collector held off for a timed loop.

    A full collection stops every thread of the process for as long as it walks the heap:
    0.1 s with a calibration's libraries loaded, more in a long-lived process. That is
    longer than a Modbus setpoint lead or many SYNC periods, so one collection at the wrong
    moment spoils a recording (CI refused a 0.5 s Modbus run for a 25 ms pause, in a test
    process whose collections took that long). Reference counting still frees what the
    loop drops; cycles wait for the collector's return.
    """
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()
