"""No garbage collection inside a timed acquisition loop: a full collection stops every
thread for 0.1 s or more in a long-lived process (a Modbus run in CI was refused for a 25 ms
pause in its setpoint writes). Cyclic garbage made by another thread during the run would
start collections; none may start while the loop runs, and one must start after it."""

from __future__ import annotations

import gc
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import pytest

from conftest import sine
from hil.drives.cia402.drive import CanOpenDrive
from hil.drives.emulated import canopen_emulator, modbus_emulator
from hil.drives.modbus.drive import ModbusDrive
from hil.profile import UnitProfile
from tests.helpers import BENCH_LEAD_PERIODS

# the wall clock times its field-bus loops: run alone, not beside other tests (README)
pytestmark = pytest.mark.realtime


@dataclass
class Watch:
    starts: list[float] = field(default_factory=list)  # each collection's start
    held: list[float] = field(default_factory=list)  # times the collector was seen off


@contextmanager
def collections_seen() -> Iterator[Watch]:
    """While inside: when collections start and when the collector is off, with a thread
    making reference cycles (each one a collection's trigger once enough pile up)."""
    watch = Watch()
    done = threading.Event()

    def seen(phase: str, _: dict[str, int]) -> None:
        if phase == "start":
            watch.starts.append(time.monotonic())

    def churn() -> None:
        while not done.is_set():
            for _ in range(2000):
                cycle: list[object] = []
                cycle.append(cycle)
            if not gc.isenabled():
                watch.held.append(time.monotonic())
            time.sleep(0.001)

    gc.callbacks.append(seen)
    worker = threading.Thread(target=churn, daemon=True)
    worker.start()
    try:
        yield watch
    finally:
        done.set()
        worker.join()
        gc.callbacks.remove(seen)


@pytest.mark.parametrize("kind", ["canopen", "modbus"])
def test_no_collection_runs_during_an_excitation(profile: UnitProfile, kind: str) -> None:
    emulator = canopen_emulator if kind == "canopen" else modbus_emulator
    backend = CanOpenDrive if kind == "canopen" else ModbusDrive
    # the churning thread shares the GIL with the host and the in-process emulator: pauses
    # of up to 51 ms in 15 runs at 100 Hz (20-26 ms without it), beyond the Modbus station's
    # default lead of 3 periods; a lead of 6 bridges them (the subject here is the collector)
    lead = ({"station_changes": {"setpoint_lead_periods": BENCH_LEAD_PERIODS}}
            if kind == "modbus" else {})
    with (emulator(profile, seed=3, **lead) as (_, station),
          backend(station, limits=profile.limits) as drive):
        drive.enable()
        excitation = sine(0.3, fs_hz=min(drive.info.max_sample_rate_hz, 500.0))
        with collections_seen() as watch:
            time.sleep(0.2)
            drive.run(excitation)
            time.sleep(0.2)
    assert watch.starts, "the churn made no collection: the test cannot see one"
    assert watch.held, "the collector was never held"
    first, last = min(watch.held), max(watch.held)
    # the CANopen emulator's station runs in lockstep, faster than real time: how long the
    # run lasts is the machine's (0.08 s on a fast one), how often it was seen held is not
    assert len(watch.held) >= 20, f"seen held {len(watch.held)} times in {last - first:.3f} s"
    during = [t for t in watch.starts if first <= t <= last]
    assert during == [], f"{len(during)} collection(s) while the loop ran"
    assert max(watch.starts) > last, "no collection after the run: the collector was left off"
    assert gc.isenabled()
