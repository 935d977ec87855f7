"""The resonance protocol's excitations against the Cramér–Rao bound per second of motion.

Issue 13 ("designed excitation"): the stepped sine the azimuth demo ran before (24
frequencies 6–300 Hz, each with its own 0.12 s settling; ``crb_frf.STEPPED_SINE``) against
the designed periodic multisine of the profile's ``[protocols.resonance]`` (log-spaced lines
plus a dense band on the period's grid, one settling period). For each, over ``--runs``
simulated runs (seeds 0…runs−1):

- the Cramér–Rao bound of (f_r, f_a, ζ_r) from the two-mass model's Fisher information for
  that excitation (J, ζ_a, B/J, τ free as the fit has them), conditional on the measured
  motion with the simulator's white torque noise on the reported torque (machinery and
  assumptions in ``crb_common.py``; numeric Jacobian of the model response). Stepped sine:
  per block of whole periods (``crb_frf``); multisine: per period and line, the covariance of
  the line's Fourier coefficient from :func:`hil.identify.multisine.period_phasors`'s design
  (constant, ramp and every line fitted jointly);
- its value per second of motion: the information ``1/CRB²`` divided by the excitation's
  duration (the measured run, without the repositioning move), and the multisine's gain
  over the stepped sine in it;
- the estimator's Monte-Carlo scatter (std) and RMSE against that bound, and its bias.

Cases: **demo unit** (every effect of the azimuth demo plant on: cogging, K_t ripple, cable,
encoder, load noise) and **white** (two-mass load, friction, current-loop lag, torque noise
only; the physics step refined 64 × as in ``bench_crb.py``).

    nice -n 10 python -m benchmarks.bench_excitation --runs 200
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass

import numpy as np

import hil.suite.resonance as protocol
from benchmarks import crb_frf
from benchmarks.crb_common import (
    ComplexArray,
    FloatArray,
    FrfBlocks,
    MonteCarlo,
    Parameter,
    bare_firmware,
    bound,
    frf_information,
    monte_carlo,
    sim_drive,
)
from hil.errors import IdentificationError
from hil.identify.multisine import crest_factor, period_phasors
from hil.identify.resonance import TwoMassModel, two_mass_response
from hil.profile import UnitProfile, load_profile
from hil.recording import Recording
from plant_sim.params import PlantParams

AZIMUTH = "demo_gimbal_azimuth"
SUBSTEPS = 64  # the white case's physics step, as bench_crb.py's resonance rows
ESTIMATED = (3, 1, 4)  # log f_r, log f_a, log ζ_r in TwoMassModel.as_vector()


def multisine_blocks(recording: Recording, spec: protocol.MultisineSpec, *, sigma: float
                     ) -> list[FrfBlocks]:
    """Per line: the analysed periods' position phasors and the torque-noise covariance of
    each period's Fourier coefficient (white noise ``sigma`` through the joint design)."""
    window = spec.analysed(spec.periods)
    n = round(spec.period_s * spec.fs_hz)
    harmonics = spec.harmonics
    position = period_phasors(recording.position[window], period_samples=n,
                              periods=spec.periods, harmonics=harmonics)
    phase = 2 * math.pi * np.outer(np.arange(n) / n, np.asarray(harmonics, dtype=np.float64))
    ramp = (np.arange(n) - (n - 1) / 2) / n
    design = np.column_stack([np.ones(n), ramp, np.cos(phase), np.sin(phase)])
    covariance = sigma**2 * np.linalg.inv(design.T @ design)
    k_count = len(harmonics)
    flip = np.diag([1.0, -1.0])  # (c, s) → (Re, Im) of c − j·s
    blocks = []
    for k, h in enumerate(harmonics):
        index = [2 + k, 2 + k_count + k]
        cs = flip @ covariance[np.ix_(index, index)] @ flip
        blocks.append(FrfBlocks(frequency_hz=h / spec.period_s, position=position[:, k],
                                covariance=np.repeat(cs[None], spec.periods, axis=0)))
    return blocks


def _bounds(points: list[FrfBlocks], truth: TwoMassModel, fs_hz: float) -> list[float]:
    freqs = np.array([p.frequency_hz for p in points])
    theta = truth.as_vector()

    def model(x: FloatArray) -> ComplexArray:
        return two_mass_response(TwoMassModel.from_vector(x), freqs, fs_hz=fs_hz)

    info = frf_information(points, model, theta, np.full(theta.size, 1e-5))
    values = np.exp(theta)
    grads = np.zeros((3, theta.size))
    for row, index in enumerate(ESTIMATED):
        grads[row, index] = values[index]
    return list(bound(info, grads))


def multisine(profile: UnitProfile, plant: PlantParams, runs: int, case: str) -> MonteCarlo:
    """f_res, f_anti, ζ_res of the profile's multisine against their bounds."""
    truth = crb_frf.two_mass_truth(
        plant, time_constant_s=profile.firmware.current_loop_time_constant_s)
    result = MonteCarlo(estimator="multisine", case=case, parameters=(
        Parameter(name="f_res", truth=truth.resonance_hz),
        Parameter(name="f_anti", truth=truth.antiresonance_hz),
        Parameter(name="ζ_res", truth=truth.resonance_damping)))
    fs = profile.sample_rate_hz

    def one(seed: int) -> tuple[list[float], list[float]] | None:
        drive = sim_drive(plant, firmware=profile.firmware, limits=profile.limits, fs_hz=fs,
                          seed=seed)
        spec = protocol.MultisineSpec.from_profile(profile, drive.info)
        *moves, measured = protocol.excitation(spec, position_rad=drive.status().position_rad)
        for move in moves:
            drive.run(move)
        recording = drive.run(measured)
        try:
            found = protocol.analyse(recording, spec)
        except IdentificationError:
            return None
        points = multisine_blocks(recording, spec, sigma=plant.torque_noise_nm)
        m = found.model
        return ([m.resonance_hz, m.antiresonance_hz, m.resonance_damping],
                _bounds(points, truth, fs))

    return monte_carlo(result, runs, one)


@dataclass(frozen=True, slots=True)
class Excitation:
    """One excitation's Monte Carlo and its measured run's duration."""

    name: str
    motion_s: float
    result: MonteCarlo


def durations_s(profile: UnitProfile, plant: PlantParams) -> tuple[float, float, float]:
    """The measured runs' durations (stepped sine, multisine) and the multisine's crest
    factor (its lines alone, one period)."""
    info = sim_drive(plant, firmware=profile.firmware,
                     limits=profile.limits, fs_hz=profile.sample_rate_hz, seed=0).info
    stepped = protocol.SteppedSpec.from_profile(crb_frf.stepped_sine_profile(profile), info)
    designed = protocol.MultisineSpec.from_profile(profile, info)
    stepped_s = protocol.excitation(stepped, position_rad=0.0)[-1].duration_s
    designed_s = protocol.excitation(designed, position_rad=0.0)[-1].duration_s
    return stepped_s, designed_s, crest_factor(designed.lines_command(periods=1))


def table(rows: list[tuple[str, Excitation, Excitation]]) -> str:
    """Markdown: per case and parameter, both excitations side by side."""
    lines = [
        "| case | parameter | excitation | motion s | CRB | info / s (1/CRB²/s) | gain / s "
        "| std / CRB | RMSE / CRB | bias | runs |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for case, stepped, designed in rows:
        before = {r["parameter"]: r for r in stepped.result.rows()}
        for ex in (stepped, designed):
            for r in ex.result.rows():
                name = str(r["parameter"])
                per_s = 1.0 / (float(r["crb"]) ** 2 * ex.motion_s)
                base = 1.0 / (float(before[name]["crb"]) ** 2 * stepped.motion_s)
                failed = f" ({ex.result.failures} failed)" if ex.result.failures else ""
                lines.append(
                    f"| {case} | {name} | {ex.name} | {ex.motion_s:.2f} | {float(r['crb']):.3g} "
                    f"| {per_s:.3g} | {per_s / base:.2f} | {float(r['std_over_crb']):.2f} "
                    f"| {float(r['rmse_over_crb']):.2f} | {float(r['bias']):+.2f} % "
                    f"| {r['runs']}{failed} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--runs", type=int, default=200, help="Monte Carlo runs per case")
    args = parser.parse_args()
    started = time.perf_counter()
    profile = load_profile(AZIMUTH)
    assert profile.plant is not None
    stepped_s, designed_s, crest = durations_s(profile, profile.plant)
    white = crb_frf.resonance_white(profile.plant, substeps=SUBSTEPS)
    lagged = bare_firmware(profile, keep_lag=True)
    rows = []
    for case, prof, plant in ((f"white (substeps {SUBSTEPS})", lagged, white),
                              ("demo unit", profile, profile.plant)):
        rows.append((case,
                     Excitation("stepped sine", stepped_s,
                                crb_frf.resonance(prof, plant, args.runs, case)),
                     Excitation("multisine", designed_s,
                                multisine(prof, plant, args.runs, case))))
    print(table(rows))
    print(f"\nmultisine crest factor {crest:.2f} (lines alone, one period); {args.runs} runs "
          f"per case, {time.perf_counter() - started:.0f} s wall in all")


if __name__ == "__main__":
    main()
