"""Stepped-sine experiments against their Cramér–Rao bounds: current-loop lag and two-mass
resonance (bounds explained in ``bench_crb.py``)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from types import ModuleType
from typing import Any

import numpy as np

import hil.suite.current_loop as current_protocol
import hil.suite.resonance as resonance_protocol
from benchmarks.crb_common import (
    ComplexArray,
    FloatArray,
    FrfBlocks,
    MonteCarlo,
    Parameter,
    bare_plant,
    bound,
    frf_blocks,
    frf_information,
    monte_carlo,
    sim_drive,
)
from hil.characterise.truth import reported_scale, two_mass_truth
from hil.errors import IdentificationError
from hil.identify.current_loop import sampled_response
from hil.identify.resonance import TwoMassModel, two_mass_response
from hil.profile import UnitProfile
from hil.recording import Recording
from plant_sim.params import PlantParams

SegmentSamples = Callable[[float], int]


def _blocks(
    recording: Recording,
    frequencies_hz: tuple[float, ...],
    *,
    start: int,
    settle: SegmentSamples,
    segment: SegmentSamples,
    fs_hz: float,
    blocks: int,
    sigma: float,
) -> list[FrfBlocks]:
    """Per frequency the samples the protocol's ``analyse`` hands to the estimator."""
    out = []
    for f in frequencies_hz:
        a, b = start + settle(f), start + segment(f)
        out.append(
            frf_blocks(
                recording.time_s[a:b],
                recording.position[a:b],
                frequency_hz=f,
                fs_hz=fs_hz,
                blocks=blocks,
                sigma=sigma,
            )
        )
        start += segment(f)
    return out


def _stepped_sine(
    protocol: ModuleType, spec: Any, drive: Any, *, sigma: float, fs_hz: float
) -> tuple[Any, list[FrfBlocks], FloatArray] | None:
    """Run a stepped-sine protocol's excitation on ``drive``: its result (None if it could
    not identify), the per-frequency blocks its estimator used, and the frequencies."""
    move, sines = protocol.excitation(spec, position_rad=drive.status().position_rad)
    drive.run(move)
    recording = drive.run(sines)
    try:
        found = protocol.analyse(recording, spec)
    except IdentificationError:
        return None
    points = _blocks(
        recording,
        spec.frequencies_hz,
        start=round(spec.ramp_s * fs_hz),
        settle=spec.settle_samples,
        segment=spec.segment_samples,
        fs_hz=fs_hz,
        blocks=spec.blocks,
        sigma=sigma,
    )
    return found, points, np.array(spec.frequencies_hz)


# -------------------------------------------------------------------------- current loop


def current_loop(profile: UnitProfile, plant: PlantParams, runs: int, case: str) -> MonteCarlo:
    """τ against three bounds: from the complex FRF points (J, B/J, τ free), from their
    phases only (a free magnitude per frequency: what the phase fit can use), and from the
    complex points with a dead time free as well, of τ + d (what is certified: a dead time
    is fitted beside τ on every recording, ``hil.identify.lag_model``; at d = 0 the
    estimate's bound d ≥ 0 makes this bound a reference, not a limit)."""
    tau_ms = profile.firmware.current_loop_time_constant_s * 1e3
    inertia = plant.total_inertia_kg_m2 * reported_scale(plant)
    b_over_j = plant.viscous_nm_s_rad / plant.total_inertia_kg_m2
    result = MonteCarlo(
        estimator="current_loop",
        case=case,
        parameters=(
            Parameter(name="τ (bound: complex FRF)", truth=tau_ms),
            Parameter(name="τ (bound: FRF phases only)", truth=tau_ms),
            Parameter(name="τ + d (bound: complex FRF, dead time free)", truth=tau_ms),
        ),
    )
    sigma = plant.torque_noise_nm
    fs = profile.sample_rate_hz

    def one(seed: int) -> tuple[list[float], list[float]] | None:
        drive = sim_drive(plant, firmware=profile.firmware, limits=profile.limits, fs_hz=fs,
                          seed=seed)
        spec = current_protocol.Spec.from_profile(profile, drive.info)
        ran = _stepped_sine(current_protocol, spec, drive, sigma=sigma, fs_hz=fs)
        if ran is None:
            return None
        found, points, freqs = ran

        def model(x: FloatArray) -> ComplexArray:
            return sampled_response(
                freqs,
                fs_hz=fs,
                inertia_kg_m2=math.exp(x[2]),
                viscous_over_inertia_1_s=float(x[1]),
                time_constant_s=float(x[0]) * 1e-3,
            )

        def phases(x: FloatArray) -> ComplexArray:
            h = model(np.array([x[0], x[1], 0.0]))
            return np.asarray(np.exp(x[2:]) * h / np.abs(h), dtype=np.complex128)

        full = np.array([tau_ms, b_over_j, math.log(inertia)])
        steps = np.array([1e-4, 1e-3, 1e-5])
        crb_full = bound(frf_information(points, model, full, steps), np.eye(3)[0])[0]
        h0 = model(full)
        phase_only = np.concatenate([[tau_ms, b_over_j], np.log(np.abs(h0))])
        steps_phase = np.concatenate([[1e-4, 1e-3], np.full(len(freqs), 1e-5)])
        info = frf_information(points, phases, phase_only, steps_phase)
        crb_phase = bound(info, np.eye(info.shape[0])[0])[0]

        def delayed(x: FloatArray) -> ComplexArray:
            return np.asarray(model(x[:3]) * np.exp(-2j * math.pi * freqs * x[3] * 1e-3),
                              dtype=np.complex128)

        crb_sum = bound(frf_information(points, delayed, np.append(full, 0.0),
                                        np.append(steps, 1e-4)), np.array([1.0, 0, 0, 1.0]))[0]
        value = found.time_constant.value
        return [value] * 3, [float(crb_full), float(crb_phase), float(crb_sum)]

    return monte_carlo(result, runs, one)


def current_loop_white(plant: PlantParams) -> PlantParams:
    """Rigid axis, Coulomb + viscous friction, torque noise (run with
    ``bare_firmware(profile, keep_lag=True)``: the current-loop lag kept)."""
    return bare_plant(plant)


# ----------------------------------------------------------------------------- resonance

# the azimuth demo's stepped sine before the designed multisine (issue 13): what these
# benchmarks measure as "the stepped sine"
STEPPED_SINE = {"excitation": "stepped_sine", "band_hz": [6.0, 300.0], "points": 24,
                "speed_rad_s": 0.5, "amplitude_rad_s": 0.25, "amplitude_knee_hz": 15.0,
                "max_amplitude_rad_s": 0.6, "segment_s": 0.1, "min_periods": 5,
                "settle_s": 0.12, "blocks": 5}


def stepped_sine_profile(profile: UnitProfile) -> UnitProfile:
    """``profile`` with its ``[protocols.resonance]`` table replaced by :data:`STEPPED_SINE`."""
    return dataclasses.replace(profile, protocols={**profile.protocols,
                                                   "resonance": STEPPED_SINE})


def resonance(
    profile: UnitProfile,
    plant: PlantParams,
    runs: int,
    case: str,
    *,
    settle_s: float | None = None,
) -> MonteCarlo:
    """f_res, f_anti, ζ_res. ``settle_s``: a diagnostic that overrides the profile's
    settling time per frequency (the travel limits widened to make room: the simulator has
    no end stops); ``None`` runs the protocol as the profile sets it. Always the stepped
    sine (:data:`STEPPED_SINE`); ``bench_excitation.py`` measures the multisine."""
    profile = stepped_sine_profile(profile)
    truth = two_mass_truth(plant, time_constant_s=profile.firmware.current_loop_time_constant_s)
    result = MonteCarlo(
        estimator="resonance",
        case=case,
        parameters=(
            Parameter(name="f_res", truth=truth.resonance_hz),
            Parameter(name="f_anti", truth=truth.antiresonance_hz),
            Parameter(name="ζ_res", truth=truth.resonance_damping),
        ),
    )
    sigma = plant.torque_noise_nm
    fs = profile.sample_rate_hz
    theta = truth.as_vector()

    def one(seed: int) -> tuple[list[float], list[float]] | None:
        limits = profile.limits
        if settle_s is not None:
            limits = dataclasses.replace(limits, travel_min_rad=-30.0, travel_max_rad=30.0)
        drive = sim_drive(plant, firmware=profile.firmware, limits=limits, fs_hz=fs, seed=seed)
        spec = resonance_protocol.SteppedSpec.from_profile(profile, drive.info)
        if settle_s is not None:
            spec = dataclasses.replace(spec, settle_s=settle_s)
        ran = _stepped_sine(resonance_protocol, spec, drive, sigma=sigma, fs_hz=fs)
        if ran is None:
            return None
        found, points, freqs = ran

        def model(x: FloatArray) -> ComplexArray:
            return two_mass_response(TwoMassModel.from_vector(x), freqs, fs_hz=fs)

        info = frf_information(points, model, theta, np.full(theta.size, 1e-5))
        values = np.exp(theta)
        grads = np.zeros((3, theta.size))
        for row, index in enumerate((3, 1, 4)):  # log f_r, log f_a, log ζ_r
            grads[row, index] = values[index]
        crb = bound(info, grads)
        m = found.model
        return [m.resonance_hz, m.antiresonance_hz, m.resonance_damping], list(crb)

    return monte_carlo(result, runs, one)


def resonance_white(plant: PlantParams, *, substeps: int) -> PlantParams:
    """Two-mass load, Coulomb + viscous friction, current-loop lag, torque noise; the
    simulator's physics step refined ``substeps`` times per control period."""
    return bare_plant(plant).with_changes(
        load_inertia_kg_m2=plant.load_inertia_kg_m2,
        shaft_stiffness_nm_rad=plant.shaft_stiffness_nm_rad,
        shaft_damping_nm_s_rad=plant.shaft_damping_nm_s_rad,
        inertia_elevation_kg_m2=plant.inertia_elevation_kg_m2,
        substeps=substeps,
    )
