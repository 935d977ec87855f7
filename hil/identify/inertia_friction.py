"""J, B and T_c from sinusoidal-velocity runs by orthogonal correlation (the source article).

With ``ω = V·sin(2πft + φ)`` over whole periods, the torque's Fourier components along the
velocity are ``s = B·V + T_c·4/π`` (in phase) and ``c = J·V·2πf`` (quadrature). Runs at two
or more amplitudes separate B (slope of s over V) from T_c (intercept).

Phase reference is the *measured* velocity, from a harmonic fit of the encoder position
(no filter lag), so a lagging velocity loop or velocity filter does not leak in-phase
torque into the inertia. Standard uncertainties are Type A: the scatter of the per-period
components (``std/√P``, ``P − 1`` degrees of freedom), propagated linearly with
Welch–Satterthwaite degrees of freedom.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hil.errors import IdentificationError
from hil.identify.estimate import Estimate, combine_linear
from hil.recording import Recording

FloatArray = NDArray[np.float64]
COULOMB_FUNDAMENTAL = 4.0 / math.pi  # fundamental of sgn(sin)
POSITION_HARMONICS = 15


def orthogonal_components(
    signal: FloatArray, *, time_s: FloatArray, frequency_hz: float
) -> tuple[float, float]:
    """The article's ``c = (2/N)·Σ x·cos`` and ``s = (2/N)·Σ x·sin`` at ``frequency_hz``.

    Computed as least-squares amplitudes of cos, sin and a constant: identical to the sums
    for uniform sampling over whole periods, and still unbiased for irregular timestamps.
    """
    omega = 2 * math.pi * frequency_hz
    design = np.column_stack([np.cos(omega * time_s), np.sin(omega * time_s), np.ones_like(time_s)])
    coefficients = np.linalg.lstsq(design, signal, rcond=None)[0]
    return float(coefficients[0]), float(coefficients[1])


def harmonic_design(time_s: FloatArray, *, frequency_hz: float, harmonics: int) -> FloatArray:
    """Columns ``1, cos(kωt), sin(kωt)`` for k = 1..harmonics."""
    omega = 2 * math.pi * frequency_hz
    columns = [np.ones_like(time_s)]
    for k in range(1, harmonics + 1):
        columns += [np.cos(k * omega * time_s), np.sin(k * omega * time_s)]
    return np.column_stack(columns)


@dataclass(frozen=True, slots=True, kw_only=True)
class SineRun:
    """One sine run reduced to its components along the measured velocity."""

    frequency_hz: float
    velocity_amplitude_rad_s: float
    velocity_phase_rad: float
    quadrature_nm: float  # c
    quadrature_u_nm: float
    in_phase_nm: float  # s
    in_phase_u_nm: float
    periods: int
    samples: int
    noise_rms_nm: float  # non-periodic torque (noise, loop jitter)
    # phase-free kinematics and measured torque over the analysis window
    time_s: FloatArray
    velocity_rad_s: FloatArray
    acceleration_rad_s2: FloatArray
    torque_nm: FloatArray
    phase_bin: NDArray[np.intp]  # index of each sample's phase bin within the period


PHASE_BINS = 200


def synchronous_average(signal: FloatArray, phase_bin: NDArray[np.intp]) -> FloatArray:
    """Each sample replaced by the mean of its phase bin over all periods (the periodic
    part of ``signal``); what is left over is noise and non-periodic motion."""
    counts = np.bincount(phase_bin, minlength=PHASE_BINS)
    sums = np.bincount(phase_bin, weights=signal, minlength=PHASE_BINS)
    means = np.divide(sums, counts, out=np.zeros(PHASE_BINS), where=counts > 0)
    return means[phase_bin]


def analyse_sine_run(recording: Recording, *, frequency_hz: float, settle_periods: int) -> SineRun:
    """Reduce one sinusoidal-velocity run (starting at the recording's first sample).

    The first ``settle_periods`` are discarded; every following whole period is used.
    """
    time_s = recording.time_s - recording.time_s[0]
    dt = float(np.median(np.diff(time_s)))
    total = math.floor((time_s[-1] + dt) * frequency_hz + 1e-6)
    periods = total - settle_periods
    if periods < 2:
        raise IdentificationError(
            f"{recording.source}: {total} whole periods at {frequency_hz} Hz, "
            f"need at least {settle_periods + 2} ({settle_periods} settling + 2)"
        )
    start, stop = settle_periods / frequency_hz, total / frequency_hz
    window = (time_s >= start - 1e-9) & (time_s < stop - 1e-9)
    t = time_s[window]
    position = recording.position[window]
    torque = recording.effort[window]

    per_period = [
        _period_components(t, position, torque, frequency_hz, k)
        for k in range(settle_periods, total)
    ]
    quadrature = np.array([p[0] for p in per_period])
    in_phase = np.array([p[1] for p in per_period])
    amplitude = np.array([p[2] for p in per_period])
    phase = np.array([p[3] for p in per_period])

    design = harmonic_design(t, frequency_hz=frequency_hz, harmonics=POSITION_HARMONICS)
    trend = np.column_stack([design, t])
    pos_coef = np.linalg.lstsq(trend, position, rcond=None)[0]
    velocity, acceleration = _harmonic_derivatives(t, pos_coef, frequency_hz)
    phase_bin = np.minimum(
        (np.mod(t * frequency_hz, 1.0) * PHASE_BINS).astype(np.intp), PHASE_BINS - 1
    )
    torque_periodic = synchronous_average(torque, phase_bin)
    dof = max(len(t) - PHASE_BINS, 1)
    noise_rms = float(np.sqrt(np.sum((torque - torque_periodic) ** 2) / dof))

    return SineRun(
        frequency_hz=frequency_hz,
        velocity_amplitude_rad_s=float(amplitude.mean()),
        velocity_phase_rad=float(np.angle(np.mean(np.exp(1j * phase)))),
        quadrature_nm=float(quadrature.mean()),
        quadrature_u_nm=float(quadrature.std(ddof=1) / math.sqrt(periods)),
        in_phase_nm=float(in_phase.mean()),
        in_phase_u_nm=float(in_phase.std(ddof=1) / math.sqrt(periods)),
        periods=periods,
        samples=int(window.sum()),
        noise_rms_nm=noise_rms,
        time_s=t,
        velocity_rad_s=velocity,
        acceleration_rad_s2=acceleration,
        torque_nm=torque,
        phase_bin=phase_bin,
    )


def _period_components(
    t: FloatArray, position: FloatArray, torque: FloatArray, frequency_hz: float, k: int
) -> tuple[float, float, float, float]:
    """(c, s, V, φ) of period ``k``: torque components along the period's own velocity."""
    mask = (t >= k / frequency_hz - 1e-9) & (t < (k + 1) / frequency_hz - 1e-9)
    tk = t[mask]
    omega = 2 * math.pi * frequency_hz
    cos, sin = np.cos(omega * tk), np.sin(omega * tk)
    ones = np.ones_like(tk)
    pos = np.linalg.lstsq(
        np.column_stack([cos, sin, ones, tk - tk.mean()]), position[mask], rcond=None
    )[0]
    tor = np.linalg.lstsq(np.column_stack([cos, sin, ones]), torque[mask], rcond=None)[0]
    # x = Xc·cos + Xs·sin  →  v = ω·Xs·cos − ω·Xc·sin = V·sin(ωt + φ)
    v_sin, v_cos = -omega * pos[0], omega * pos[1]
    amplitude = math.hypot(v_sin, v_cos)
    phase = math.atan2(v_cos, v_sin)
    a, b = tor[0], tor[1]
    quadrature = a * math.cos(phase) - b * math.sin(phase)
    in_phase = b * math.cos(phase) + a * math.sin(phase)
    return quadrature, in_phase, amplitude, phase


def _harmonic_derivatives(
    t: FloatArray, coef: FloatArray, frequency_hz: float
) -> tuple[FloatArray, FloatArray]:
    """Velocity and acceleration of the fitted position (harmonics + linear trend)."""
    omega = 2 * math.pi * frequency_hz
    velocity = np.full_like(t, coef[-1])
    acceleration = np.zeros_like(t)
    for k in range(1, (len(coef) - 2) // 2 + 1):
        ck, sk = coef[2 * k - 1], coef[2 * k]
        w = k * omega
        velocity += w * (-ck * np.sin(w * t) + sk * np.cos(w * t))
        acceleration += -(w**2) * (ck * np.cos(w * t) + sk * np.sin(w * t))
    return velocity, acceleration


@dataclass(frozen=True, slots=True, kw_only=True)
class InertiaFrictionResult:
    inertia: Estimate  # kg·m²
    viscous: Estimate  # N·m·s/rad
    coulomb: Estimate  # N·m
    runs: tuple[SineRun, ...]
    fit_pct: float  # periodic torque explained by J·α + B·ω + T_c·sgn(ω)
    lack_of_fit_rms_nm: float
    noise_rms_nm: float


def identify_inertia_friction(runs: Sequence[SineRun]) -> InertiaFrictionResult:
    """J, B, T_c from two or more runs at distinct amplitudes (least squares over amplitudes).

    Raises
    ------
    IdentificationError
        Fewer than two runs, or amplitudes too close to separate B from T_c.
    """
    if len(runs) < 2:
        raise IdentificationError(f"need runs at two or more amplitudes, got {len(runs)}")
    amplitude = np.array([r.velocity_amplitude_rad_s for r in runs])
    if np.ptp(amplitude) < 0.1 * amplitude.max():
        raise IdentificationError(
            f"velocity amplitudes {np.round(amplitude, 4).tolist()} rad/s are too close "
            "to separate viscous from Coulomb friction (need ≥ 10 % spread)"
        )
    omega = np.array([2 * math.pi * r.frequency_hz for r in runs])
    dof = [r.periods - 1 for r in runs]

    # inertia: inverse-variance mean of c_i / (V_i·ω)
    j_values = [r.quadrature_nm / (v * w) for r, v, w in zip(runs, amplitude, omega, strict=True)]
    j_u = [r.quadrature_u_nm / (v * w) for r, v, w in zip(runs, amplitude, omega, strict=True)]
    inv_var = 1.0 / np.square(j_u)
    inertia = combine_linear(inv_var / inv_var.sum(), j_values, j_u, dof)

    # friction: weighted least squares of s_i = B·V_i + (4/π)·T_c
    s_u = np.array([r.in_phase_u_nm for r in runs])
    design = np.column_stack([amplitude, np.full_like(amplitude, COULOMB_FUNDAMENTAL)])
    weighted = design / s_u[:, None]
    gain = np.linalg.pinv(weighted) / s_u[None, :]  # rows: B, T_c as linear maps of s
    s_values = [r.in_phase_nm for r in runs]
    viscous = combine_linear(gain[0], s_values, s_u, dof)
    coulomb = combine_linear(gain[1], s_values, s_u, dof)

    fit_pct, lack_rms = _model_fit(runs, inertia[0], viscous[0], coulomb[0])
    noise = float(np.sqrt(np.mean([r.noise_rms_nm**2 for r in runs])))
    crb = cramer_rao_std(runs, noise_rms_nm=noise)
    return InertiaFrictionResult(
        inertia=Estimate(
            name="inertia_kg_m2",
            value=inertia[0],
            standard_uncertainty=inertia[1],
            unit="kg·m²",
            dof=inertia[2],
            cramer_rao_std=float(crb[0]),
        ),
        viscous=Estimate(
            name="viscous_nm_s_rad",
            value=viscous[0],
            standard_uncertainty=viscous[1],
            unit="N·m·s/rad",
            dof=viscous[2],
            cramer_rao_std=float(crb[1]),
        ),
        coulomb=Estimate(
            name="coulomb_nm",
            value=coulomb[0],
            standard_uncertainty=coulomb[1],
            unit="N·m",
            dof=coulomb[2],
            cramer_rao_std=float(crb[2]),
        ),
        runs=tuple(runs),
        fit_pct=fit_pct,
        lack_of_fit_rms_nm=lack_rms,
        noise_rms_nm=noise,
    )


def regressors(run: SineRun) -> FloatArray:
    """``[α, ω, sgn ω]`` over the run's analysis window (phase-free kinematics)."""
    return np.column_stack(
        [run.acceleration_rad_s2, run.velocity_rad_s, np.sign(run.velocity_rad_s)]
    )


def cramer_rao_std(runs: Sequence[SineRun], *, noise_rms_nm: float) -> FloatArray:
    """Bound on the standard deviation of (J, B, T_c) for white torque noise of
    ``noise_rms_nm``: ``sqrt(diag(σ²·(ΦᵀΦ)⁻¹))`` with Φ = [α, ω, sgn ω] (and a constant)."""
    information = np.zeros((4, 4))
    for run in runs:
        phi = np.column_stack([regressors(run), np.ones(len(run.time_s))])
        information += phi.T @ phi
    covariance = noise_rms_nm**2 * np.linalg.inv(information)
    return np.sqrt(np.diag(covariance)[:3])


def _model_fit(
    runs: Sequence[SineRun], inertia: float, viscous: float, coulomb: float
) -> tuple[float, float]:
    """Fit % of the base model to the periodic torque, and the RMS it leaves unexplained."""
    errors, signals = [], []
    for run in runs:
        predicted = regressors(run) @ np.array([inertia, viscous, coulomb])
        residual = synchronous_average(run.torque_nm - predicted, run.phase_bin)
        residual -= residual.mean()  # constant torques (gravity, offset) are not J, B, T_c
        errors.append(residual)
        periodic = synchronous_average(run.torque_nm, run.phase_bin)
        signals.append(periodic - periodic.mean())
    error = np.concatenate(errors)
    signal = np.concatenate(signals)
    fit = 100.0 * (1.0 - float(np.linalg.norm(error) / np.linalg.norm(signal)))
    return fit, float(np.sqrt(np.mean(error**2)))
