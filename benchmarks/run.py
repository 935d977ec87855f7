"""Benchmarks (not timed tests): simulator speed and estimator efficiency.

    python -m benchmarks.run [--runs 200] [--json OUT.json]

- simulator: × real time at 4 kHz, rigid and with every effect on (static or LuGre
  friction), and the demo gimbal's two
  coupled axes against its azimuth alone (``--speed-only``: these rows only);
- J, B, T_c: RMSE over Monte Carlo runs divided by the Cramér–Rao bound σ·sqrt(diag((ΦᵀΦ)⁻¹)),
  under white torque noise only, then with current-loop lag and encoder quantisation on;
- calibration machine time: the J/B/T_c protocol's commanded motion time.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time

import numpy as np

import hil.suite.inertia_friction as protocol
from hil.drives.sim import SimDrive
from hil.identify.inertia_friction import (
    HARMONICS,
    Method,
    cramer_rao_std,
    identify_inertia_friction,
)
from hil.identify.sine_run import HOLD_SAMPLES, FloatArray, analyse_sine_run
from hil.motion import Mode
from hil.profile import load_profile
from plant_sim.firmware import Firmware
from plant_sim.gimbal import AxisBlock, GimbalPlant
from plant_sim.model import Plant, simulate
from plant_sim.params import PlantParams

FS_HZ = 4000.0


def simulator_speed(params: PlantParams, firmware: Firmware, seconds: float = 60.0) -> float:
    command = 0.5 * np.sin(2 * np.pi * 2.0 * np.arange(int(seconds * FS_HZ)) / FS_HZ)
    simulate(params, mode=Mode.VELOCITY, command=command[:100], fs_hz=FS_HZ, seed=0,
             firmware=firmware)
    best = math.inf
    for _ in range(3):
        started = time.perf_counter()
        Plant(params, firmware=firmware, fs_hz=FS_HZ, seed=0).run(Mode.VELOCITY, command)
        best = min(best, time.perf_counter() - started)
    return seconds / best


def gimbal_speed(seconds: float = 60.0) -> dict[str, float]:
    """× real time of the demo gimbal: its azimuth alone, and both axes as one coupled plant
    (the azimuth's sine, the elevation held by its position loop), every effect on."""
    azimuth, elevation = load_profile("demo_gimbal_azimuth"), load_profile(
        "demo_gimbal_elevation")
    outer, inner = azimuth.plant, elevation.plant
    assert outer is not None
    assert inner is not None
    fs = azimuth.sample_rate_hz
    command = 0.5 * np.sin(2 * np.pi * 2.0 * np.arange(int(seconds * fs)) / fs)
    hold = np.zeros_like(command)

    def alone() -> None:
        Plant(outer, firmware=azimuth.firmware, fs_hz=fs, seed=0).run(Mode.VELOCITY, command)

    def coupled() -> None:
        GimbalPlant(Plant(outer, firmware=azimuth.firmware, fs_hz=fs, seed=0),
                    Plant(inner, firmware=elevation.firmware, fs_hz=fs, seed=1)).run(
            AxisBlock(mode=Mode.VELOCITY, command=command),
            AxisBlock(mode=Mode.POSITION, command=hold))

    speeds = {}
    for name, run in (("azimuth_alone", alone), ("two_axes_coupled", coupled)):
        run()  # compiled and cached before the clock starts
        best = math.inf
        for _ in range(3):
            started = time.perf_counter()
            run()
            best = min(best, time.perf_counter() - started)
        speeds[f"simulator_x_real_time_gimbal_{name}"] = seconds / best
    return speeds


# (label, method, harmonics) compared on the same Monte Carlo data
VARIANTS: tuple[tuple[str, Method, int], ...] = (
    ("orthogonal, fundamental (the article)", "orthogonal", 1),
    ("orthogonal, harmonics 1-5", "orthogonal", 5),
    ("least_squares, instrumented (default)", "least_squares", HARMONICS),
)


def efficiency(plant: PlantParams, firmware: Firmware, runs: int) -> dict[str, dict[str, float]]:
    """RMSE / CRB and bias of J, B, T_c for each variant on the same Monte Carlo data."""
    profile = load_profile()
    truth = np.array([plant.inertia_kg_m2, plant.viscous_nm_s_rad, plant.coulomb_nm])
    errors: dict[str, list[FloatArray]] = {label: [] for label, _, _ in VARIANTS}
    bounds: list[FloatArray] = []
    for seed in range(runs):
        with SimDrive(plant, firmware=firmware, limits=profile.limits, fs_hz=FS_HZ,
                      seed=seed) as drive:
            drive.enable()
            spec = protocol.Spec.from_profile(profile, drive.info)
            recordings = [drive.run(e) for e in protocol.excitation(spec)]
        # as the protocol does after the current-loop protocol measured the lag
        hold = HOLD_SAMPLES + firmware.current_loop_time_constant_s * spec.fs_hz
        sine_runs = [
            analyse_sine_run(
                r,
                frequency_hz=spec.frequency_hz,
                settle_periods=spec.settle_periods,
                hold_samples=hold,
            )
            for r in recordings
        ]
        for label, method, harmonics in VARIANTS:
            result = identify_inertia_friction(sine_runs, method=method, harmonics=harmonics)
            values = np.array([result.inertia.value, result.viscous.value, result.coulomb.value])
            errors[label].append(values - truth)
        measured = float(np.sqrt(np.mean([r.noise_rms_nm**2 for r in sine_runs])))
        sigma = plant.torque_noise_nm if plant.torque_noise_nm > 0 else measured
        bounds.append(cramer_rao_std(sine_runs, noise_rms_nm=sigma))
    crb = np.mean(bounds, axis=0)
    names = ("inertia", "viscous", "coulomb")
    report: dict[str, dict[str, float]] = {}
    for label, _, _ in VARIANTS:
        err = np.array(errors[label])
        rmse = np.sqrt(np.mean(err**2, axis=0))
        report[label] = {
            f"{n}_rmse_over_crb": float(rmse[i] / crb[i]) for i, n in enumerate(names)
        }
        report[label] |= {
            f"{n}_bias_pct": float(100 * err[:, i].mean() / truth[i]) for i, n in enumerate(names)
        }
    return report


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--json", default=None)
    parser.add_argument("--speed-only", action="store_true",
                        help="the simulator's speed rows only (no Monte Carlo)")
    args = parser.parse_args()
    profile = load_profile()
    demo = profile.plant
    assert demo is not None
    white = PlantParams(
        inertia_kg_m2=0.0036,
        viscous_nm_s_rad=0.005,
        coulomb_nm=0.020,
        torque_noise_nm=0.002,
    )
    white_firmware = Firmware(velocity_kp_nm_s_rad=0.45, velocity_ki_nm_rad=12.0)
    lagged = dataclasses.replace(white, encoder_counts_per_rev=1 << 19)
    lagged_firmware = white_firmware.with_changes(
        current_loop_time_constant_s=3e-4, velocity_filter_hz=300.0
    )
    two_mass = dataclasses.replace(
        demo, load_inertia_kg_m2=0.004, shaft_stiffness_nm_rad=400.0, shaft_damping_nm_s_rad=0.02
    )
    report: dict[str, object] = {
        "simulator_x_real_time_rigid": simulator_speed(white, white_firmware),
        "simulator_x_real_time_all_effects": simulator_speed(demo, profile.firmware),
        "simulator_x_real_time_all_effects_two_mass": simulator_speed(two_mass, profile.firmware),
        # LuGre friction at the stiffest pre-sliding characterise draws (10 µrad)
        "simulator_x_real_time_all_effects_lugre": simulator_speed(
            dataclasses.replace(demo, presliding_rad=1e-5), profile.firmware),
        **gimbal_speed(),
    }
    if not args.speed_only:
        report |= _monte_carlo(white, white_firmware, lagged, lagged_firmware, args.runs)
    text = json.dumps(report, indent=2)
    print(text)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            handle.write(text + "\n")


def _monte_carlo(white: PlantParams, white_firmware: Firmware, lagged: PlantParams,
                 lagged_firmware: Firmware, runs: int) -> dict[str, object]:
    return {
        "jbt_white_noise": efficiency(white, white_firmware, runs),
        "jbt_lag_quantisation_filter": efficiency(lagged, lagged_firmware, runs),
        "jbt_protocol_motion_time_s": sum(
            e.duration_s
            for e in protocol.excitation(
                protocol.Spec(
                    frequency_hz=2.0,
                    amplitudes_rad_s=(0.5, 1.0),
                    settle_periods=2,
                    periods=8,
                    fs_hz=FS_HZ,
                )
            )
        ),
        "monte_carlo_runs": runs,
    }


if __name__ == "__main__":
    main()
