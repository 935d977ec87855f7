"""The cross-coupling estimator against its Cramér–Rao bound, with its coverage.

    python -m benchmarks.bench_coupling [--runs 100] [--json OUT.json]

Monte Carlo over noise seeds of the demo gimbal (its azimuth and elevation simulated as one
coupled plant, every per-axis effect on): the cross-coupling protocol's motion and fit, as a
calibration runs them, the azimuth's J taken 3 % off its truth (as the sine protocol might
give it). Per product of inertia: bias, RMSE over the bound ``σ·sqrt(diag((XᵀX)⁻¹))`` of
the fit's own design (σ from its residual), the share of runs whose ±U holds the truth and
the RMS of error/u. The truth is in reported-torque units (the drive's nominal K_t).
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

from hil.drives.base import Drive
from hil.drives.connect import open_drive
from hil.identify.cross_coupling import fit_cross_coupling
from hil.profile import load_profile
from hil.recording import Recording
from hil.suite.cross_coupling import Spec, coupling_runs, motion


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=100)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    azimuth, elevation = load_profile("demo_gimbal_azimuth"), load_profile(
        "demo_gimbal_elevation")
    plant = azimuth.plant
    assert plant is not None
    gain = 1.0 + plant.torque_constant_error_rel
    truth = {"coupling_product_level_kg_m2": plant.inertia_coupling_level_kg_m2 / gain,
             "coupling_product_vertical_kg_m2": plant.inertia_coupling_vertical_kg_m2 / gain}
    rows: dict[str, list[tuple[float, float, float, float]]] = {name: [] for name in truth}
    started = time.perf_counter()
    motion_s = 0.0
    for seed in range(args.runs):
        with open_drive("sim", profile=azimuth, unit_serial="SIM-0001", seed=seed,
                        gimbal_axes={"elevation": elevation}) as drive:
            spec = Spec.from_profile(azimuth, drive.info)
            drive.enable()
            passes: dict[str, Recording] = {}

            def where(moved: Drive = drive) -> float:
                return moved.status().position_rad

            for e in motion(spec, position=where, set_elevation=drive.set_elevation):
                passes[e.name] = drive.run(e)
                motion_s += e.duration_s if seed == 0 else 0.0
        found = fit_cross_coupling(coupling_runs(spec, passes),
                                   azimuth_inertia_kg_m2=1.03 * plant.total_inertia_kg_m2 / gain)
        for estimate in (found.level, found.vertical):
            assert estimate.cramer_rao_std is not None
            rows[estimate.name].append((estimate.value, estimate.standard_uncertainty,
                                        estimate.expanded_uncertainty,
                                        estimate.cramer_rao_std))
    report: dict[str, object] = {"runs": args.runs, "motion_time_s_per_run": motion_s,
                                 "wall_time_s": time.perf_counter() - started}
    for name, values in rows.items():
        value, u, expanded, bound = (np.array(column) for column in zip(*values, strict=True))
        error = value - truth[name]
        report[name] = {
            "truth": truth[name],
            "bias_pct": 100 * float(np.mean(error)) / truth[name],
            "rmse_over_crb": float(np.sqrt(np.mean(error**2)) / np.mean(bound)),
            "std_over_crb": float(np.std(value) / np.mean(bound)),
            "coverage": float(np.mean(np.abs(error) <= expanded)),
            "rms_error_over_u": float(math.sqrt(np.mean((error / u) ** 2))),
            "mean_u_over_crb": float(np.mean(u / bound)),
        }
    text = json.dumps(report, indent=2)
    print(text)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            handle.write(text + "\n")


if __name__ == "__main__":
    main()
