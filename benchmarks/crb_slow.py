"""Constant-speed experiments against their Cramér–Rao bounds: Stribeck staircase, gravity
and cable sweep, cogging passes (bounds explained in ``bench_crb.py``)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

import hil.suite.cogging as cogging_protocol
import hil.suite.gravity_cable as gravity_protocol
import hil.suite.stribeck as stribeck_protocol
from benchmarks.crb_common import (
    FloatArray,
    MonteCarlo,
    Parameter,
    bare_plant,
    bound,
    linear_information,
    monte_carlo,
    sim_drive,
)
from hil.characterise.truth import reported_scale
from hil.errors import IdentificationError
from hil.identify.cogging import _design
from hil.identify.quantisation import quantisation_step
from hil.identify.stribeck import BLOCKS, _settled_start
from hil.profile import UnitProfile
from plant_sim.params import PlantParams

IntArray = NDArray[np.intp]

# ---------------------------------------------------------------------------- Stribeck


def _stribeck_block_counts(
    forward: tuple[FloatArray, FloatArray],
    backward: tuple[FloatArray, FloatArray],
    *,
    speed_rad_s: float,
    settle_s: float,
    resolution_rad: float,
    counts_per_window: float = 20.0,
) -> list[tuple[int, int]]:
    """Samples per matched position block of each direction, selected as
    :func:`hil.identify.stribeck.speed_point` selects them."""
    window_s = max(0.02, counts_per_window * resolution_rad / speed_rad_s)
    ranges = []
    for (t, p), sign in ((forward, 1.0), (backward, -1.0)):
        start = _settled_start(
            t, p, sign * speed_rad_s, settle_s=settle_s, window_s=window_s, tolerance=0.2
        )
        ranges.append(p[start:])
    pf, pb = ranges
    low, high = max(pf.min(), pb.min()), min(pf.max(), pb.max())
    edges = np.linspace(low, high, BLOCKS + 1)
    counts = []
    for k in range(BLOCKS):
        n = [int(((p >= edges[k]) & (p < edges[k + 1])).sum()) for p in (pf, pb)]
        if min(n) >= 2:
            counts.append((n[0], n[1]))
    return counts


def stribeck_crb(speeds: FloatArray, information: FloatArray, truth: Sequence[float]) -> FloatArray:
    """Bound on (T_c, T_s, v_s, B) from the friction information ``I_s`` at each speed.

    Per sample ``τ = L_{s,k} ± F(v_s)`` with a free load ``L`` per speed and position block
    (what the half difference cancels); eliminating ``L`` leaves ``I_s = Σ_k 4/(σ²(1/n₊ +
    1/n₋))`` on ``F(v_s)``, and ``F = Σ_s I_s ∇F ∇Fᵀ`` with ``F(v) = T_c + (T_s − T_c)·
    exp(−(v/v_s)²) + B·v``.
    """
    tc, ts, vs, _ = truth
    e = np.exp(-((speeds / vs) ** 2))
    grad = np.column_stack([1 - e, e, (ts - tc) * e * 2 * speeds**2 / vs**3, speeds])
    fisher = grad.T @ (grad * information[:, None])
    return bound(fisher, np.eye(4))


def stribeck(
    profile: UnitProfile,
    plant: PlantParams,
    runs: int,
    case: str,
    *,
    exact_torque_hold: bool = True,
    earlier_inputs: bool = False,
) -> MonteCarlo:
    """``earlier_inputs``: analyse as a calibration does, with the K_t ripple table and the
    cable loop's half-width its earlier protocols measure (here their true values, so the
    staircase's own bias shows apart from theirs)."""
    scale = reported_scale(plant)
    ripple = (tuple((h.order, h.amplitude, h.phase_rad) for h in plant.kt_ripple)
              if earlier_inputs else ())
    half_width = plant.cable_hysteresis_nm * scale if earlier_inputs else 0.0
    truth = (
        plant.coulomb_nm * scale,
        max(plant.static_friction_nm, plant.coulomb_nm) * scale,
        plant.stribeck_velocity_rad_s,
        plant.viscous_nm_s_rad * scale,
    )
    result = MonteCarlo(
        estimator="stribeck",
        case=case,
        parameters=(
            Parameter(name="T_c", truth=truth[0]),
            Parameter(name="T_s", truth=truth[1]),
            Parameter(name="v_s", truth=truth[2]),
            Parameter(name="B", truth=truth[3]),
        ),
    )
    sigma = plant.torque_noise_nm

    def one(seed: int) -> tuple[list[float], list[float]] | None:
        drive = sim_drive(plant, firmware=profile.firmware,
            limits=profile.limits,
            fs_hz=profile.sample_rate_hz,
            seed=seed,
            exact_torque_hold=exact_torque_hold,
        )
        spec = stribeck_protocol.Spec.from_profile(profile, drive.info)
        move, stairs = stribeck_protocol.excitation(spec, position_rad=drive.status().position_rad)
        drive.run(move)
        rec = drive.run(stairs)
        try:
            found = stribeck_protocol.analyse(rec.time_s, rec.position, rec.effort, spec,
                                              ripple=ripple)
        except IdentificationError:
            return None
        plan = spec.stairs
        resolution = quantisation_step(rec.position)
        speeds, info = [], []
        for point, v, (a, b), (c, d) in zip(
            found.points, plan.speeds_rad_s, plan.forward_steps, plan.backward_steps, strict=True
        ):
            if point.stick_slip or not math.isfinite(point.friction_nm):
                continue
            counts = _stribeck_block_counts(
                (rec.time_s[a:b], rec.position[a:b]),
                (rec.time_s[c:d], rec.position[c:d]),
                speed_rad_s=v,
                settle_s=spec.settle_s,
                resolution_rad=resolution,
            )
            speeds.append(point.speed_rad_s)
            info.append(sum(4 / (sigma**2 * (1 / nf + 1 / nb)) for nf, nb in counts))
        crb = stribeck_crb(np.array(speeds), np.array(info), truth)
        values = [
            found.coulomb.value - half_width,
            found.static.value - half_width,
            found.stribeck_velocity.value,
            found.viscous.value,
        ]
        return values, list(crb)

    return monte_carlo(result, runs, one)


def stribeck_white(plant: PlantParams) -> PlantParams:
    """Friction (Coulomb, viscous, Stribeck) and torque noise only."""
    return bare_plant(plant).with_changes(
        static_friction_nm=plant.static_friction_nm,
        stribeck_velocity_rad_s=plant.stribeck_velocity_rad_s,
    )


# ----------------------------------------------------------------------- gravity, cable


def gravity_crb(
    position: FloatArray,
    torque_sign: FloatArray,
    bin_index: IntArray,
    *,
    sigma: float,
    mge: float,
    phase: float,
) -> FloatArray:
    """Bound on (m·g·e, φ, k_cable) from the load fit's samples: ``τ = a·cos θ + b·sin θ +
    k·θ + c + s·F_bin`` (``s`` = ±1 by direction, a free ``F`` per position bin: what the
    half sum cancels), ``a = m·g·e·cos φ``, ``b = −m·g·e·sin φ``."""
    bins = int(bin_index.max()) + 1
    nuisance = np.zeros((position.size, bins))
    nuisance[np.arange(position.size), bin_index] = torque_sign
    jac = np.column_stack(
        [np.cos(position), np.sin(position), position, np.ones_like(position), nuisance]
    )
    fisher = linear_information(jac, sigma)
    a, b = mge * math.cos(phase), -mge * math.sin(phase)
    grads = np.zeros((3, jac.shape[1]))
    grads[0, :2] = [a / mge, b / mge]
    grads[1, :2] = [b / mge**2, -a / mge**2]
    grads[2, 2] = 1.0
    return bound(fisher, grads)


def hysteresis_crb(
    s_probe: FloatArray,
    probe_bin: IntArray,
    ref_bin: IntArray,
    *,
    sigma: float,
    half_width_nm: float,
    angle_rad: float,
) -> float:
    """Bound on the hysteresis half width ``h``: probe samples ``τ = L_bin + c + 2h·exp(−s/s₀)``,
    reference samples (the settled pass at the same positions) ``τ = L_bin``; free ``c``,
    ``s₀`` and ``L`` per travel bin (what the estimator's bin differences cancel)."""
    bins = int(max(probe_bin.max(), ref_bin.max())) + 1
    e = np.exp(-s_probe / angle_rad)
    probe = np.zeros((s_probe.size, 3 + bins))
    probe[:, 0] = 1.0
    probe[:, 1] = 2 * e
    probe[:, 2] = 2 * half_width_nm * e * s_probe / angle_rad**2
    probe[np.arange(s_probe.size), 3 + probe_bin] = 1.0
    ref = np.zeros((ref_bin.size, 3 + bins))
    ref[np.arange(ref_bin.size), 3 + ref_bin] = 1.0
    jac = np.vstack([probe, ref])
    used = np.flatnonzero(np.abs(jac).sum(axis=0) > 0)  # bins without samples drop out
    grad = np.zeros(used.size)
    grad[int(np.flatnonzero(used == 1)[0])] = 1.0
    return float(bound(linear_information(jac[:, used], sigma), grad)[0])


def gravity_cable(profile: UnitProfile, plant: PlantParams, runs: int, case: str) -> MonteCarlo:
    scale = reported_scale(plant)
    mge, phase = plant.gravity_mge_nm * scale, plant.gravity_phase_rad
    h, s0 = plant.cable_hysteresis_nm * scale, plant.cable_hysteresis_angle_rad
    result = MonteCarlo(
        estimator="gravity_cable",
        case=case,
        parameters=(
            Parameter(name="m·g·e", truth=mge),
            Parameter(name="φ", truth=phase, relative=False, unit="rad"),
            Parameter(name="k_cable", truth=plant.cable_stiffness_nm_rad * scale),
            Parameter(name="hysteresis h", truth=h),
        ),
    )
    sigma = plant.torque_noise_nm

    def one(seed: int) -> tuple[list[float], list[float]] | None:
        drive = sim_drive(plant, firmware=profile.firmware, limits=profile.limits,
                          fs_hz=profile.sample_rate_hz, seed=seed)
        spec = gravity_protocol.Spec.from_profile(profile, drive.info)
        move, sweep = gravity_protocol.excitation(spec, position_rad=drive.status().position_rad)
        drive.run(move)
        rec = drive.run(sweep)
        try:
            found = gravity_protocol.analyse(rec.position, rec.effort, spec)
        except IdentificationError:
            return None
        plan = spec.plan
        (a0, a1), (b0, b1), (c0, c1) = plan.up, plan.down, plan.probe
        p1, p2 = rec.position[a0:a1], rec.position[b0:b1]
        p_ref = rec.position[plan.reference[0]:plan.reference[1]]
        # the load fit's samples: bins of both passes inside the excluded ends (as
        # hil.identify.gravity_cable.identify_gravity_cable bins them)
        low = max(p1.min(), p2.min()) + spec.exclude_rad
        high = min(p1.max(), p2.max()) - spec.exclude_rad
        edges = np.linspace(low, high, spec.bins + 1)
        i1, i2 = np.digitize(p1, edges) - 1, np.digitize(p2, edges) - 1
        pos, sign, index = [], [], []
        used = 0
        for k in range(spec.bins):
            m1, m2 = i1 == k, i2 == k
            if m1.sum() < 5 or m2.sum() < 5:
                continue
            pos += [p1[m1], p2[m2]]
            sign += [np.ones(int(m1.sum())), -np.ones(int(m2.sum()))]
            index.append(np.full(int(m1.sum() + m2.sum()), used))
            used += 1
        crb = list(
            gravity_crb(
                np.concatenate(pos),
                np.concatenate(sign),
                np.concatenate(index),
                sigma=sigma,
                mge=mge,
                phase=phase,
            )
        )
        # the hysteresis fit's samples (as gravity_cable._hysteresis selects them)
        p_probe = rec.position[c0:c1]
        reversal = float(p_probe.max())
        s = reversal - p_probe
        edges = np.linspace(spec.probe_settle_s * spec.probe_speed_rad_s, float(s.max()), 41)
        s_used, probe_bin, ref_bin = [], [], []
        used = 0
        for lo, hi in itertools.pairwise(edges):
            m = (s >= lo) & (s < hi)
            j = (p_ref >= reversal - hi) & (p_ref < reversal - lo)
            if m.sum() < 3 or j.sum() < 3:
                continue
            s_used.append(s[m])
            probe_bin.append(np.full(int(m.sum()), used))
            ref_bin.append(np.full(int(j.sum()), used))
            used += 1
        crb.append(
            hysteresis_crb(
                np.concatenate(s_used),
                np.concatenate(probe_bin),
                np.concatenate(ref_bin),
                sigma=sigma,
                half_width_nm=h,
                angle_rad=s0,
            )
        )
        values = [found.mge.value, found.phase.value, found.stiffness.value, found.hysteresis.value]
        return values, crb

    return monte_carlo(result, runs, one)


def gravity_white(plant: PlantParams) -> PlantParams:
    """Coulomb + viscous friction, gravity, cable spring and hysteresis, torque noise."""
    return bare_plant(plant).with_changes(
        gravity_mge_nm=plant.gravity_mge_nm,
        gravity_phase_rad=plant.gravity_phase_rad,
        cable_stiffness_nm_rad=plant.cable_stiffness_nm_rad,
        cable_zero_rad=plant.cable_zero_rad,
        cable_hysteresis_nm=plant.cable_hysteresis_nm,
        cable_hysteresis_angle_rad=plant.cable_hysteresis_angle_rad,
    )


# ------------------------------------------------------------------------------ cogging


def _components(amplitude: float, phase_rad: float) -> tuple[float, float]:
    """(cos, sin) coefficients of ``amplitude·sin(nθ + phase)``."""
    return amplitude * math.sin(phase_rad), amplitude * math.cos(phase_rad)


def cogging(profile: UnitProfile, plant: PlantParams, runs: int, case: str) -> MonteCarlo:
    scale = reported_scale(plant)
    cog = {h.order: (h.amplitude * scale, h.phase_rad) for h in plant.cogging}
    rip = {h.order: (h.amplitude, h.phase_rad) for h in plant.kt_ripple}
    parameters = [Parameter(name=f"cogging n={n}", truth=a) for n, (a, _) in cog.items()]
    parameters += [Parameter(name=f"K_t ripple n={n}", truth=a) for n, (a, _) in rip.items()]
    result = MonteCarlo(estimator="cogging", case=case, parameters=tuple(parameters))
    sigma = plant.torque_noise_nm
    inertia = profile.measurement("inertia_kg_m2").nominal  # the protocol's fallback

    def one(seed: int) -> tuple[list[float], list[float]] | None:
        drive = sim_drive(plant, firmware=profile.firmware, limits=profile.limits,
                          fs_hz=profile.sample_rate_hz, seed=seed)
        spec = cogging_protocol.Spec.from_profile(profile, drive.info)
        move, passes = cogging_protocol.excitation(spec, position_rad=drive.status().position_rad)
        drive.run(move)
        rec = drive.run(passes)
        try:
            found = cogging_protocol.analyse(
                rec.time_s, rec.position, rec.effort, spec, inertia_kg_m2=inertia
            )
        except IdentificationError:
            return None
        orders = [h.order for h in found.cogging]
        # the passes as test_cogging.analyse cuts them
        n = spec.pass_samples
        skip = math.ceil(spec.skip_rad / spec.speed_rad_s * spec.fs_hz)
        thetas = [rec.position[a:b] for a, b in ((skip, n), (n + skip, 2 * n))]
        poly = 6
        lo, hi = min(float(t.min()) for t in thetas), max(float(t.max()) for t in thetas)
        centre, half = (lo + hi) / 2, (hi - lo) / 2
        # per pass p: poly_p(θ) + Σ_n cos(nθ)·(g_c − T̄_p·r_c) + sin(nθ)·(g_s − T̄_p·r_s)
        width = 2 * (poly + 1) + 4 * len(orders)
        blocks = []
        for p, (theta, level) in enumerate(zip(thetas, found.torque_levels_nm, strict=True)):
            jac = np.zeros((theta.size, width))
            design = _design(theta, orders, poly, centre, half)
            jac[:, p * (poly + 1) : (p + 1) * (poly + 1)] = design[:, : poly + 1]
            for k in range(len(orders)):
                cs = design[:, poly + 1 + 2 * k : poly + 3 + 2 * k]
                base = 2 * (poly + 1) + 4 * k
                jac[:, base : base + 2] = cs
                jac[:, base + 2 : base + 4] = -level * cs
            blocks.append(jac)
        fisher = linear_information(np.vstack(blocks), sigma)
        covariance = np.linalg.inv(fisher)
        values, crb = [], []
        for table, offset, estimates in ((cog, 0, found.cogging), (rip, 2, found.kt_ripple)):
            by_order = {h.order: h.amplitude for h in estimates}
            for order, (amplitude, phase) in table.items():
                if order not in orders:
                    values.append(math.nan)
                    crb.append(math.nan)
                    continue
                base = 2 * (poly + 1) + 4 * orders.index(order) + offset
                c, s = _components(amplitude, phase)
                g = np.array([c, s]) / amplitude
                cov = covariance[base : base + 2, base : base + 2]
                values.append(by_order[order])
                crb.append(math.sqrt(float(g @ cov @ g)))
        return values, crb

    return monte_carlo(result, runs, one)


def cogging_white(plant: PlantParams) -> PlantParams:
    """Coulomb + viscous friction, cogging, K_t ripple and torque noise."""
    return bare_plant(plant).with_changes(cogging=plant.cogging, kt_ripple=plant.kt_ripple)
