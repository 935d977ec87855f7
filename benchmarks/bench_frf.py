"""Benchmark (not a timed test): correlation FRF against a Welch/FFT H1 on the same data.

    python -m benchmarks.bench_frf [--runs 20] [--json OUT.json]

The resonance protocol's stepped sine is simulated on the azimuth demo unit (every effect
on: noise, quantisation, lag, cogging, Stribeck, cable...) with ``--runs`` noise seeds. On
each recording the FRF position/torque is estimated at the stepped frequencies by

- correlation: the protocol's per-frequency orthogonal correlation (H1 over blocks of
  whole periods, :func:`hil.identify.resonance.frf_point`);
- Welch: ``scipy.signal.csd / welch`` on the same samples of each frequency (Hann
  segments one block long, 50 % overlap, linear detrend), read at the excitation's bin.

Reported per frequency: the relative error of each against the true sampled-data response
of the simulated plant (bias and spread over the seeds), and the ratio of their variances.
Near the resonance the "truth" carries the simulator's own time discretisation (its f_r sits
~0.3 % high), which both estimators show as a few % bias there.

Result (10 runs): similar variance (median Welch/correlation ≈ 0.8: Hann segments with 50 %
overlap average a little more), but Welch is biased by leakage where the FRF changes fast
(≈ 40 % at the anti-resonance, 2–4 % elsewhere below it); the correlation is not.
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
from scipy import signal

import hil.suite.resonance as protocol
from benchmarks.crb_frf import stepped_sine_profile
from hil.drives.base import DriveInfo
from hil.drives.sim import SimDrive
from hil.identify.resonance import TwoMassModel, frf_point, two_mass_response
from hil.motion import Mode
from hil.profile import load_profile


def _welch_h1(position: np.ndarray, torque: np.ndarray, *, frequency_hz: float, fs_hz: float,
              blocks: int) -> complex:
    """Welch H1 over the same samples: Hann segments as long as one correlation block (so
    the bin falls on the excitation), 50 % overlap, linear detrend; the bin nearest f."""
    nperseg = len(position) // blocks
    x = np.asarray(torque, dtype=np.float64)
    y = np.asarray(position, dtype=np.float64)
    bins, s_tt = signal.welch(x, fs=fs_hz, nperseg=nperseg, detrend="linear")  # type: ignore[call-overload]
    _, s_tp = signal.csd(x, y, fs=fs_hz, nperseg=nperseg, detrend="linear")  # type: ignore[call-overload]
    k = int(np.abs(bins - frequency_hz).argmin())
    return complex(s_tp[k] / s_tt[k])  # csd(x, y) = conj(X)·Y: H1 = S_xy / S_xx


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()

    profile = load_profile("demo_gimbal_azimuth")
    plant = profile.plant
    assert plant is not None
    fs = profile.sample_rate_hz
    info = DriveInfo(vendor="bench", model="bench", firmware_version="0", serial="0",
                     rated_torque_nm=0.5, limits=profile.limits, modes=tuple(Mode),
                     max_sample_rate_hz=fs)
    spec = protocol.SteppedSpec.from_profile(stepped_sine_profile(profile), info)
    freqs = np.array(spec.frequencies_hz)
    j_total = plant.total_inertia_kg_m2
    j_load = plant.load_at_elevation_kg_m2
    wa = math.sqrt(plant.shaft_stiffness_nm_rad / j_load)
    reduced = plant.inertia_kg_m2 * j_load / j_total
    wr = math.sqrt(plant.shaft_stiffness_nm_rad / reduced)
    c = plant.shaft_damping_nm_s_rad
    truth_model = TwoMassModel(  # torque as the drive reports it: K_t error scales J
        inertia_kg_m2=j_total / (1 + plant.torque_constant_error_rel),
        antiresonance_hz=wa / (2 * math.pi), antiresonance_damping=c / (2 * math.sqrt(
            plant.shaft_stiffness_nm_rad * j_load)),
        resonance_hz=wr / (2 * math.pi), resonance_damping=c / (2 * math.sqrt(
            plant.shaft_stiffness_nm_rad * reduced)) + plant.viscous_nm_s_rad / (
            2 * plant.inertia_kg_m2 * wr) * j_load / j_total,
        viscous_over_inertia_1_s=plant.viscous_nm_s_rad / j_total,
        time_constant_s=profile.firmware.current_loop_time_constant_s)
    truth = two_mass_response(truth_model, freqs, fs_hz=fs)

    corr_err, welch_err = [], []
    for seed in range(args.runs):
        with SimDrive(plant, firmware=profile.firmware, limits=profile.limits, fs_hz=fs,
                      seed=seed) as drive:
            drive.enable()
            move, sine = protocol.excitation(spec, position_rad=drive.status().position_rad)
            drive.run(move)
            rec = drive.run(sine)
        command = rec.velocity_cmd
        assert command is not None
        start = round(spec.ramp_s * fs)
        corr: list[complex] = []
        welch_list: list[complex] = []
        for f in spec.frequencies_hz:
            a, b = start + spec.settle_samples(f), start + spec.segment_samples(f)
            corr.append(frf_point(rec.time_s[a:b], rec.position[a:b], rec.effort[a:b],
                                  command[a:b], frequency_hz=f, fs_hz=fs,
                                  blocks=spec.blocks).frf_rad_nm)
            welch_list.append(_welch_h1(rec.position[a:b], rec.effort[a:b], frequency_hz=f,
                                        fs_hz=fs, blocks=spec.blocks))
            start = b
        welch = np.asarray(welch_list)
        corr_err.append(np.asarray(corr) / truth - 1)
        welch_err.append(welch / truth - 1)

    ce, we = np.array(corr_err), np.array(welch_err)
    rows = []
    print(f"{'f Hz':>7} {'corr bias %':>11} {'corr std %':>10} {'welch bias %':>12} "
          f"{'welch std %':>11} {'var ratio W/C':>13}")
    for k, f in enumerate(freqs):
        row = {
            "frequency_hz": float(f),
            "correlation_bias_pct": 100 * float(np.abs(ce[:, k].mean())),
            "correlation_std_pct": 100 * float(np.sqrt(np.mean(np.abs(ce[:, k] - ce[:, k].mean())
                                                                ** 2))),
            "welch_bias_pct": 100 * float(np.abs(we[:, k].mean())),
            "welch_std_pct": 100 * float(np.sqrt(np.mean(np.abs(we[:, k] - we[:, k].mean())
                                                          ** 2))),
        }
        row["variance_ratio_welch_over_correlation"] = (
            row["welch_std_pct"] / max(row["correlation_std_pct"], 1e-12)) ** 2
        rows.append(row)
        print(f"{f:7.1f} {row['correlation_bias_pct']:11.3f} {row['correlation_std_pct']:10.3f} "
              f"{row['welch_bias_pct']:12.3f} {row['welch_std_pct']:11.3f} "
              f"{row['variance_ratio_welch_over_correlation']:13.1f}")
    ratios = [r["variance_ratio_welch_over_correlation"] for r in rows]
    print(f"median variance ratio (Welch / correlation): {float(np.median(ratios)):.1f}")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as out:
            json.dump({"runs": args.runs, "points": rows}, out, indent=2)


if __name__ == "__main__":
    main()
