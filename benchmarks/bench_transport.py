"""Transport benchmark: how much faster than real time do runs over the emulators go?

Runs the J/B/T_c excitation of the demo profile (2 Hz velocity sine, both amplitudes)
through ``drive.run()`` over the CANopen emulator (real CAN frames on a python-can virtual
bus, SYNC-clocked plant) and reports wall time against the excitation's duration; for
comparison the in-process simulator. Not a timed test: run it by hand,
``python -m benchmarks.bench_transport [--repeat N]``.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from hil.drives.connect import open_drive
from hil.motion import Excitation, Mode
from hil.profile import load_profile


def sine_excitations(fs_hz: float, settings: dict[str, object]) -> list[Excitation]:
    frequency = float(settings["frequency_hz"])  # type: ignore[arg-type]
    periods = int(settings.get("settle_periods", 2)) + int(settings.get("periods", 8))  # type: ignore[call-overload]
    t = np.arange(round(periods * fs_hz / frequency)) / fs_hz
    return [
        Excitation(
            name=f"sine_{a:g}",
            mode=Mode.VELOCITY,
            command=float(a) * np.sin(2 * math.pi * frequency * t),
            fs_hz=fs_hz,
        )
        for a in settings["amplitudes_rad_s"]  # type: ignore[attr-defined]
    ]


def bench(kind: str, repeat: int) -> tuple[float, float, float]:
    profile = load_profile()
    settings = dict(profile.protocol("inertia_friction"))
    with open_drive(kind, profile=profile, unit_serial="BENCH-1", seed=1) as drive:
        fs = min(profile.sample_rate_hz, drive.info.max_sample_rate_hz)
        excitations = sine_excitations(fs, settings)
        drive.enable()
        best = math.inf
        for _ in range(repeat):
            start = time.perf_counter()
            for excitation in excitations:
                drive.run(excitation)
            best = min(best, time.perf_counter() - start)
    duration = sum(e.duration_s for e in excitations)
    return duration, best, fs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--kinds", nargs="+", default=["canopen-emulator", "sim"])
    args = parser.parse_args()
    for kind in args.kinds:
        duration, wall, fs = bench(kind, args.repeat)
        print(
            f"{kind:<18} {fs:>6.0f} Hz  excitation {duration:6.2f} s  wall {wall:6.2f} s  "
            f"speed {duration / wall:6.2f}x real time"
        )


if __name__ == "__main__":
    main()
