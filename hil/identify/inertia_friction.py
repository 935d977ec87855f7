"""J, B and T_c from sinusoidal-velocity runs by orthogonal correlation (the source article).

With ``ω = V·sin(2πft)`` over whole periods, the torque's Fourier components are
``c = J·V·2πf`` (cos) and ``s = B·V + T_c·4/π`` (sin); runs at two or more amplitudes
separate B (slope of s over V) from T_c (intercept).

Under a velocity loop the motion is not exactly that sine, so the regression is done with
the *measured* regressors α, ω and sgn ω (phase-free derivatives of the encoder position),
over periods and amplitudes. Samples near velocity reversal (|ω| below ``REVERSAL_BAND``·V)
are left out: there the axis sticks while the loop ramps its torque through ±T_c, so the
torque is not ``T_c·sgn(ω)`` and would bias J by the dwell.

``method="least_squares"`` (the default) fits the samples in the time domain, so B and T_c
keep the information sgn ω carries in its odd harmonics (19 % of its power): at the
Cramér–Rao bound, where the article's fundamental-only correlation reaches 1.35–1.5 × it.
Encoder quantisation makes the differentiated α noisy, and noise in a regressor biases
plain least squares towards zero (J −0.33 % with a 19-bit encoder), so α and ω are
instrumented by their first ``INSTRUMENT_HARMONICS`` harmonics of the excitation.
``method="orthogonal"`` is the article's correlation: the components along cos and sin of
the fundamental (or of harmonics ``1..harmonics``) per period, α and ω instrumented by their
mean over periods. It ignores broadband torques a time-domain fit partly absorbs (strong
commensurate cogging biases its J about half as much) at the cost of efficiency.

Standard uncertainties are Type A by delete-one-period jackknife (robust to coloured noise
and loop jitter), ``P − 1`` degrees of freedom for ``P`` periods in all.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from hil.errors import IdentificationError
from hil.identify.estimate import Estimate, combine_linear
from hil.identify.gravity_cable import CableLoop, cable_loop_torque_nm
from hil.identify.kinematics import phase_free_derivatives
from hil.recording import Recording

FloatArray = NDArray[np.float64]
Method = Literal["orthogonal", "least_squares"]
COULOMB_FUNDAMENTAL = 4.0 / math.pi  # fundamental of sgn(sin)
REVERSAL_BAND = 0.15  # fraction of the velocity amplitude
DERIVATIVE_WINDOW_PERIODS = 0.02  # Savitzky–Golay window, in periods of the sine
PHASE_BINS = 200
INSTRUMENT_HARMONICS = 7
HARMONICS = 1  # harmonics the orthogonal correlation uses (the article: the fundamental)
HOLD_SAMPLES = 0.5  # the drive holds each reported torque over the following period


def orthogonal_components(
    signal: FloatArray, *, time_s: FloatArray, frequency_hz: float
) -> tuple[float, float]:
    """The article's ``c = (2/N)·Σ x·cos`` and ``s = (2/N)·Σ x·sin`` at ``frequency_hz``.

    Computed as least-squares amplitudes of cos, sin and a constant: identical to the sums
    for uniform sampling over whole periods, and still unbiased for irregular timestamps
    or a subset of samples.
    """
    omega = 2 * math.pi * frequency_hz
    design = np.column_stack([np.cos(omega * time_s), np.sin(omega * time_s), np.ones_like(time_s)])
    coefficients = np.linalg.lstsq(design, signal, rcond=None)[0]
    return float(coefficients[0]), float(coefficients[1])


@dataclass(frozen=True, slots=True, kw_only=True)
class SineRun:
    """One sine run over its analysis window: the article's components and the samples."""

    frequency_hz: float
    velocity_amplitude_rad_s: float
    quadrature_nm: float  # c: torque along cos of the measured velocity phase
    quadrature_u_nm: float
    in_phase_nm: float  # s: torque along the measured velocity
    in_phase_u_nm: float
    periods: int
    noise_rms_nm: float  # non-periodic torque (noise, loop jitter)
    time_s: FloatArray
    velocity_rad_s: FloatArray  # phase-free
    acceleration_rad_s2: FloatArray  # phase-free
    torque_nm: FloatArray
    period: NDArray[np.intp]  # period index of each sample, 0..periods-1
    phase_bin: NDArray[np.intp]  # phase bin of each sample within its period
    moving: NDArray[np.bool_]  # outside the reversal band

    @property
    def inertia_kg_m2(self) -> float:
        """J of this run alone, ``c / (V·2πf)``."""
        return self.quadrature_nm / (
            self.velocity_amplitude_rad_s * 2 * math.pi * self.frequency_hz
        )


def synchronous_average(signal: FloatArray, phase_bin: NDArray[np.intp]) -> FloatArray:
    """Each sample replaced by the mean of its phase bin over all periods (the periodic
    part of ``signal``); what is left over is noise and non-periodic motion."""
    counts = np.bincount(phase_bin, minlength=PHASE_BINS)
    sums = np.bincount(phase_bin, weights=signal, minlength=PHASE_BINS)
    means = np.divide(sums, counts, out=np.zeros(PHASE_BINS), where=counts > 0)
    return means[phase_bin]


def analyse_sine_run(
    recording: Recording,
    *,
    frequency_hz: float,
    settle_periods: int,
    hold_samples: float = HOLD_SAMPLES,
) -> SineRun:
    """Reduce one sinusoidal-velocity run (phase zero at the recording's first sample).

    The first ``settle_periods`` are discarded; every following whole period is used.
    ``hold_samples``: the torque reported at sample k is held by the drive over the next
    period, so the motion it causes is centred that many samples later; the kinematics are
    taken there (0.5 for a zero-order hold; 0 for torque already time-aligned with motion).
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
    velocity, acceleration = phase_free_derivatives(
        recording.position, time_s=time_s, window_s=DERIVATIVE_WINDOW_PERIODS / frequency_hz
    )
    if hold_samples:
        shifted = time_s + hold_samples * dt
        velocity = np.interp(shifted, time_s, velocity)
        acceleration = np.interp(shifted, time_s, acceleration)
    cycles = time_s * frequency_hz
    window = (cycles >= settle_periods - 1e-9) & (cycles < total - 1e-9)
    t, torque = time_s[window], recording.effort[window]
    v, a = velocity[window], acceleration[window]
    period = np.minimum((cycles[window] - settle_periods).astype(np.intp), periods - 1)
    phase_bin = np.minimum(
        (np.mod(cycles[window], 1.0) * PHASE_BINS).astype(np.intp), PHASE_BINS - 1
    )
    amplitude = math.sqrt(2.0) * float(np.sqrt(np.mean(v**2)))

    components = np.array(
        [
            _along_velocity(t[period == k], v[period == k], torque[period == k], frequency_hz)
            for k in range(periods)
        ]
    )
    periodic = synchronous_average(torque, phase_bin)
    noise_rms = float(np.sqrt(np.sum((torque - periodic) ** 2) / max(len(t) - PHASE_BINS, 1)))
    return SineRun(
        frequency_hz=frequency_hz,
        velocity_amplitude_rad_s=amplitude,
        quadrature_nm=float(components[:, 0].mean()),
        quadrature_u_nm=float(components[:, 0].std(ddof=1) / math.sqrt(periods)),
        in_phase_nm=float(components[:, 1].mean()),
        in_phase_u_nm=float(components[:, 1].std(ddof=1) / math.sqrt(periods)),
        periods=periods,
        noise_rms_nm=noise_rms,
        time_s=t,
        velocity_rad_s=v,
        acceleration_rad_s2=a,
        torque_nm=torque,
        period=period,
        phase_bin=phase_bin,
        moving=np.abs(v) > REVERSAL_BAND * amplitude,
    )


def _along_velocity(
    t: FloatArray, velocity: FloatArray, torque: FloatArray, frequency_hz: float
) -> tuple[float, float]:
    """(c, s): torque components along cos and sin of the period's measured velocity phase."""
    v_cos, v_sin = orthogonal_components(velocity, time_s=t, frequency_hz=frequency_hz)
    phase = math.atan2(v_cos, v_sin)  # v ≈ V·sin(ωt + φ)
    a, b = orthogonal_components(torque, time_s=t, frequency_hz=frequency_hz)
    return a * math.cos(phase) - b * math.sin(phase), b * math.cos(phase) + a * math.sin(phase)


@dataclass(frozen=True, slots=True, kw_only=True)
class InertiaFrictionResult:
    inertia: Estimate  # kg·m²
    viscous: Estimate  # N·m·s/rad
    coulomb: Estimate  # N·m
    runs: tuple[SineRun, ...]
    method: Method
    fit_pct: float  # periodic torque of moving samples explained by J·α + B·ω + T_c·sgn(ω)
    lack_of_fit_rms_nm: float
    noise_rms_nm: float


def identify_inertia_friction(
    runs: Sequence[SineRun], *, method: Method = "least_squares", harmonics: int = HARMONICS
) -> InertiaFrictionResult:
    """J, B, T_c from two or more runs at distinct amplitudes; ``harmonics``: how many
    harmonics of the excitation the orthogonal correlation uses (1: the article's).

    Raises
    ------
    IdentificationError
        Fewer than two runs, amplitudes too close to separate B from T_c, or too few
        moving samples.
    """
    if len(runs) < 2:
        raise IdentificationError(f"need runs at two or more amplitudes, got {len(runs)}")
    amplitude = np.array([r.velocity_amplitude_rad_s for r in runs])
    if np.ptp(amplitude) < 0.1 * amplitude.max():
        raise IdentificationError(
            f"velocity amplitudes {np.round(amplitude, 4).tolist()} rad/s are too close "
            "to separate viscous from Coulomb friction (need ≥ 10 % spread)"
        )
    blocks = [
        block
        for index, run in enumerate(runs)
        for block in _run_blocks(run, index, len(runs), method, harmonics)
    ]
    theta, u, dof = _jackknife(blocks)
    noise = float(np.sqrt(np.mean([r.noise_rms_nm**2 for r in runs])))
    crb = cramer_rao_std(runs, noise_rms_nm=noise)
    fit_pct, lack_rms = _model_fit(runs, theta)
    names = (("inertia_kg_m2", "kg·m²"), ("viscous_nm_s_rad", "N·m·s/rad"), ("coulomb_nm", "N·m"))
    inertia, viscous, coulomb = (
        Estimate(
            name=name,
            value=float(theta[i]),
            standard_uncertainty=float(u[i]),
            unit=unit,
            dof=dof,
            cramer_rao_std=float(crb[i]),
        )
        for i, (name, unit) in enumerate(names)
    )
    return InertiaFrictionResult(
        inertia=inertia,
        viscous=viscous,
        coulomb=coulomb,
        runs=tuple(runs),
        method=method,
        fit_pct=fit_pct,
        lack_of_fit_rms_nm=lack_rms,
        noise_rms_nm=noise,
    )


Block = tuple[FloatArray, FloatArray]  # (AᵀA, Aᵀy) of one period


def regressors(run: SineRun, index: int, n_runs: int) -> FloatArray:
    """``[α, ω, sgn ω, 1 for run ``index``]`` for every sample of ``run``; one constant per run
    absorbs torques that do not change within it (gravity at that position, offsets)."""
    constants = np.zeros((len(run.time_s), n_runs))
    constants[:, index] = 1.0
    return np.column_stack(
        [run.acceleration_rad_s2, run.velocity_rad_s, np.sign(run.velocity_rad_s), constants]
    )


def instruments(run: SineRun, index: int, n_runs: int) -> FloatArray:
    """The regressors with α and ω replaced by their first ``INSTRUMENT_HARMONICS``
    harmonics of the excitation: the periodic motion without the encoder's quantisation
    noise, which the derivatives amplify at high frequency (instrumental variables)."""
    columns = regressors(run, index, n_runs)
    omega_t = 2 * math.pi * run.frequency_hz * run.time_s
    basis = np.column_stack(
        [np.ones_like(omega_t)]
        + [f(k * omega_t) for k in range(1, INSTRUMENT_HARMONICS + 1) for f in (np.cos, np.sin)]
    )
    smooth = basis @ np.linalg.lstsq(basis, columns[:, :2], rcond=None)[0]
    columns[:, :2] = smooth
    return columns


def _run_blocks(
    run: SineRun, index: int, n_runs: int, method: Method, harmonics: int
) -> list[Block]:
    """The normal equations of each period of ``run``, instrumented: α and ω are correlated
    against their noise-free counterparts (errors in a regressor bias least squares)."""
    if method == "least_squares":
        phi, z = regressors(run, index, n_runs), instruments(run, index, n_runs)
        blocks = []
        for k in range(run.periods):
            used = (run.period == k) & run.moving
            blocks.append((z[used].T @ phi[used], z[used].T @ run.torque_nm[used]))
        return blocks
    rows, rhs = zip(
        *(_harmonic_components(run, k, harmonics) for k in range(run.periods)), strict=True
    )
    # the periodic motion's components: the mean over periods, free of each period's noise
    motion = np.mean(rows, axis=0)[:, :2]
    blocks = []
    for r, y in zip(rows, rhs, strict=True):
        z = r.copy()
        z[:, :2] = motion
        blocks.append((z.T @ r, z.T @ y))
    return blocks


def _harmonic_components(
    run: SineRun, k: int, harmonics: int
) -> tuple[FloatArray, FloatArray]:
    """Orthogonal correlation of period ``k``: the components of α, ω, sgn ω (rows) and of
    the torque along cos and sin of harmonics ``1..harmonics`` (a constant absorbed)."""
    used = (run.period == k) & run.moving
    phi = regressors(run, 0, 1)[used][:, :3]
    omega_t = 2 * math.pi * run.frequency_hz * run.time_s[used]
    basis = np.column_stack(
        [f(n * omega_t) for n in range(1, harmonics + 1) for f in (np.cos, np.sin)]
        + [np.ones_like(omega_t)]
    )
    projector = np.linalg.pinv(basis)[:-1]
    return projector @ phi, projector @ run.torque_nm[used]


def _jackknife(blocks: list[Block]) -> tuple[FloatArray, FloatArray, float]:
    """Estimate, delete-one-block jackknife standard uncertainty, and dof (= blocks − 1)."""
    normal = np.sum([b[0] for b in blocks], axis=0)
    rhs = np.sum([b[1] for b in blocks], axis=0)
    size = 3
    try:
        theta = np.linalg.solve(normal, rhs)[:size]
        leave_out = np.array([np.linalg.solve(normal - n, rhs - r)[:size] for n, r in blocks])
    except np.linalg.LinAlgError as exc:
        raise IdentificationError(
            "J, B and T_c are not separable from these runs (too few moving samples?)"
        ) from exc
    count = len(blocks)
    spread = leave_out - leave_out.mean(axis=0)
    u = np.sqrt((count - 1) / count * np.sum(spread**2, axis=0))
    return theta, u, float(count - 1)


def cramer_rao_std(runs: Sequence[SineRun], *, noise_rms_nm: float) -> FloatArray:
    """Bound on the standard deviation of (J, B, T_c) from the samples the estimator uses,
    for white torque noise of ``noise_rms_nm``: ``sqrt(diag(σ²·(ΦᵀΦ)⁻¹))``."""
    information = np.zeros((3 + len(runs), 3 + len(runs)))
    for index, run in enumerate(runs):
        phi = regressors(run, index, len(runs))[run.moving]
        information += phi.T @ phi
    covariance = noise_rms_nm**2 * np.linalg.inv(information)
    return np.sqrt(np.diag(covariance)[:3])


def _model_fit(runs: Sequence[SineRun], theta: FloatArray) -> tuple[float, float]:
    """Fit % of the base model to the periodic torque of the moving samples, and the RMS it
    leaves unexplained (constant torques excluded)."""
    errors, signals = [], []
    for run in runs:
        phi = regressors(run, 0, 1)[:, :3]
        residual = synchronous_average(run.torque_nm - phi @ theta, run.phase_bin)[run.moving]
        periodic = synchronous_average(run.torque_nm, run.phase_bin)[run.moving]
        errors.append(residual - residual.mean())
        signals.append(periodic - periodic.mean())
    error = np.concatenate(errors)
    signal = np.concatenate(signals)
    fit = 100.0 * (1.0 - float(np.linalg.norm(error) / np.linalg.norm(signal)))
    return fit, float(np.sqrt(np.mean(error**2)))


def inertia_amplitude_spread(result: InertiaFrictionResult) -> Estimate:
    """Spread of the per-amplitude inertias ``c/(V·2πf)`` in % of their mean: a
    position-dependent torque (cogging, cable) commensurate with the sine's travel biases
    each amplitude differently and shows up here."""
    per_run = np.array([r.inertia_kg_m2 for r in result.runs])
    scale = (
        2 * math.pi * np.array([r.velocity_amplitude_rad_s * r.frequency_hz for r in result.runs])
    )
    u = np.array([r.quadrature_u_nm for r in result.runs]) / scale
    return Estimate(
        name="inertia_amplitude_spread_pct",
        value=100 * float(np.ptp(per_run) / per_run.mean()),
        standard_uncertainty=100 * float(np.sqrt(np.sum(u**2)) / per_run.mean()),
        unit="%",
        dof=float(min(r.periods for r in result.runs) - 1),
    )


def stiffness_corrected_inertia(
    inertia: Estimate, *, stiffness: Estimate, frequency_hz: float
) -> Estimate:
    """J corrected for a position stiffness ``K = dL/dθ`` at the sine's centre.

    A load torque ``L(θ)`` (gravity, cable spring) adds ``K·x`` with ``x = −V/ω·cos ωt`` to
    the torque, in the same quadrature as ``J·α``: the sine sees ``J − K/ω²``.
    """
    omega_sq = (2 * math.pi * frequency_hz) ** 2
    value, u, dof = combine_linear(
        [1.0, 1.0 / omega_sq],
        [inertia.value, stiffness.value],
        [inertia.standard_uncertainty, stiffness.standard_uncertainty],
        [inertia.dof, stiffness.dof],
    )
    return Estimate(
        name=inertia.name,
        value=value,
        standard_uncertainty=u,
        unit=inertia.unit,
        dof=dof,
        cramer_rao_std=inertia.cramer_rao_std,
    )


def torque_hold_samples(recording: Recording, *, current_loop_lag_s: float) -> float:
    """How many of the recording's samples after its position sample the torque of the same
    row acts on the shaft, plus the current loop's lag. An instantaneous torque sample is
    held over the drive's control period (the recording's own period unless
    ``control_period_s`` says otherwise): half of it. A torque averaged over the row period
    ``T_s`` (``torque_sample = "mean"``) has its centroid ``T_c − T_s/2`` after the position
    sample, which is taken a control period ``T_c`` before the row."""
    step_s = float(np.median(np.diff(recording.time_s)))
    control_s = float(recording.metadata.get("control_period_s", step_s))
    if recording.metadata.get("torque_sample") == "mean":
        mean_s = float(recording.metadata.get("torque_mean_period_s", step_s))
        hold_s = control_s - 0.5 * mean_s
    else:
        hold_s = HOLD_SAMPLES * control_s
    return (hold_s + current_loop_lag_s) / step_s


def without_cable_loop(recording: Recording, loop: CableLoop | None) -> Recording:
    """The recording with the cable's measured hysteresis torque taken out of the effort."""
    if loop is None:
        return recording
    torque = recording.effort - cable_loop_torque_nm(
        recording.position, half_width_nm=loop.half_width_nm, angle_rad=loop.angle_rad
    )
    return Recording(
        columns={**recording.columns, "torque_nm": torque},
        metadata=recording.metadata,
        source=recording.source,
        warnings=recording.warnings,
    )
