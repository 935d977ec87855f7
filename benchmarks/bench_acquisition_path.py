"""The current-loop method's error on a field bus's acquisition path, and its method line.

    python -m benchmarks.bench_acquisition_path [--units 16] [--write FILE.toml]

The simulator's method map (``fixtures/method_bias.toml``) was measured on recordings of
every control period. A CiA 402 stream at 1 kHz of a drive whose loops run at 4 kHz has
one row per 4 control periods: its torque is the last control period's (``instantaneous``)
or the period's mean (0x2077, ``mean``), its target interpolated linearly between rows, and
the images of that interpolation pass the velocity loop into the band the current-loop
estimator reads (``docs/drives.md``). This measures what that path does to τ over the
CANopen emulator: per torque sampling, units of the demo elevation with τ drawn uniformly
over its limits and a seed each, every effect on; the first half gives the bias and the
scatter beyond Type A (as ``gimbal-hil characterise --write-map`` does), the second half
how often ±U held the truth with that line applied as the calibration applies it (a band,
:func:`hil.measurement.acquisition_band`).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from hil.characterise.method_map import bias_map
from hil.characterise.run import Row
from hil.drives.cia402.drive import CanOpenDrive
from hil.drives.emulated import canopen_emulator
from hil.identify.current_loop import acquisition_path
from hil.identify.estimate import Estimate
from hil.measurement import MethodBias, with_method_terms
from hil.profile import UnitProfile, load_profile
from hil.suite import current_loop as protocol

NAME = "current_loop_time_constant_ms"
SAMPLINGS = ("mean", "instantaneous")
HEADER = """\
# The current-loop method's error on acquisition paths other than the simulator's (every
# control period), per path and axis, written by benchmarks/bench_acquisition_path.py over
# the CANopen emulator. A calibration whose recording came over such a path states a band
# of |bias| + 2·scatter (rectangular) in place of the simulator's line, which is not
# applied to another path; the band is not a correction, since the path's effect depends
# on the drive's own loop. A path without a line here gets neither.
"""


def measured(profile: UnitProfile, *, tau_ms: float, seed: int, sampling: str
             ) -> tuple[str, Row, Estimate]:
    """One unit over the emulator: the recording's acquisition path and its result."""
    unit = dataclasses.replace(profile, firmware=profile.firmware.with_changes(
        current_loop_time_constant_s=tau_ms * 1e-3))
    with (canopen_emulator(unit, seed=seed, station_changes={"torque_sample": sampling})
          as (_emulator, station),
          CanOpenDrive(station, limits=unit.limits) as drive):
        drive.enable()
        spec = protocol.Spec.from_profile(unit, drive.info)
        move, sines = protocol.excitation(spec, position_rad=drive.status().position_rad)
        drive.run(move)
        recording = drive.run(sines)
    estimate = protocol.analyse(recording, spec).time_constant
    return acquisition_path(recording.metadata, fs_hz=spec.fs_hz), Row(
        unit=f"{sampling}-{seed}", axis=profile.axis, parameter=NAME, value=estimate.value,
        truth=tau_ms, standard_uncertainty=estimate.standard_uncertainty,
        expanded_uncertainty=estimate.expanded_uncertainty), estimate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--units", type=int, default=16, help="per half and sampling")
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--write", type=Path, default=None)
    args = parser.parse_args()
    profile = load_profile()
    spec = profile.measurement(NAME)
    rng = np.random.default_rng(args.seed)
    paths: dict[str, Any] = {}
    started = time.perf_counter()
    for sampling in SAMPLINGS:
        rows: list[Row] = []
        estimates: list[Estimate] = []
        path = ""
        for unit in range(2 * args.units):
            tau_ms = float(rng.uniform(spec.lower_limit, spec.upper_limit))
            path, row, estimate = measured(profile, tau_ms=tau_ms, seed=args.seed + unit,
                                           sampling=sampling)
            rows.append(row)
            estimates.append(estimate)
        build, check = rows[:args.units], rows[args.units:]
        document = bias_map(build, population=path)["results"]
        entry = document[profile.axis][NAME]
        line = MethodBias(name=NAME, relative=entry["scale"] == "relative",
                          bias=entry["bias"], scatter=entry["scatter"], units=entry["units"],
                          acquisition=path)
        held, z = [], []
        for row, estimate in zip(check, estimates[args.units:], strict=True):
            final = with_method_terms(estimate, spec, line)
            held.append(abs(final.value - row.truth) <= final.expanded_uncertainty)
            z.append((final.value - row.truth) / final.standard_uncertainty)
        raw_errors = [(r.value - r.truth) / r.truth for r in rows]
        entry["validated_coverage"] = round(float(np.mean(held)), 4)
        entry["validated_units"] = len(check)
        paths[path] = {"results": document}
        raw_z = [(r.value - r.truth) / r.standard_uncertainty for r in rows]
        print(f"{path}: raw error {100 * np.mean(raw_errors):+.2f} % "
              f"(sd {100 * np.std(raw_errors, ddof=1):.2f} %, raw RMS error/u "
              f"{math.sqrt(np.mean(np.square(raw_z))):.2f}); "
              f"line: bias {100 * entry['bias']:+.2f} %, scatter {100 * entry['scatter']:.2f} % "
              f"({args.units} units); second half with it: ±U held {sum(held)}/{len(held)}, "
              f"RMS error/u {math.sqrt(np.mean(np.square(z))):.2f}")
    print(f"machine time {time.perf_counter() - started:.0f} s")
    if args.write is not None:
        population = (f"python -m benchmarks.bench_acquisition_path --units {args.units} "
                      f"--seed {args.seed}: {profile.axis} demo unit over the CANopen "
                      f"emulator, τ uniform over its limits")
        args.write.write_text(HEADER + tomli_w.dumps({"population": population,
                                                      "acquisition": paths}),
                              encoding="utf-8")


if __name__ == "__main__":
    main()
