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
instrumented by their first ``INSTRUMENT_HARMONICS`` harmonics of the excitation. The
instruments are weighted by a taper of the instrumented velocity out of the reversal band
(:func:`reversal_taper`), not cut at its edge: a hard cut makes the sums over each moving
stretch depend on the differentiated position's error at the stretch's two ends, which a
velocity loop makes systematic (B +1.2 % with a 19-bit encoder, lag and velocity filter).
``method="orthogonal"`` is the article's correlation: the components along cos and sin of
the fundamental (or of harmonics ``1..harmonics``) per period, α and ω instrumented by their
mean over periods. It ignores broadband torques a time-domain fit partly absorbs (strong
commensurate cogging biases its J about half as much) at the cost of efficiency.

Standard uncertainties are Type A by delete-one-period jackknife (robust to coloured noise
and loop jitter), with the degrees of freedom its variance has (:func:`jackknife_dof`: at
most ``P − 1`` for ``P`` periods in all, fewer when the periods' shares differ).
"""


from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from hil.errors import IdentificationError
from hil.identify.estimate import Component, Estimate
from hil.identify.harmonic_fit import fit_harmonics, polynomial_columns
from hil.identify.sine_run import (
    REVERSAL_BAND,
    FloatArray,
    SineRun,
    band_noise_rms_nm,
    synchronous_average,
)

Method = Literal["orthogonal", "least_squares"]
INSTRUMENT_HARMONICS = 7
HARMONICS = 1  # harmonics the orthogonal correlation uses (the article: the fundamental)
TAPER_END = 0.3  # |ω|/V where the least-squares fit's weight reaches 1 (reversal_taper)
SPREAD_BLOCK = 2  # consecutive periods the amplitude spread's jackknife deletes at once
BOUND_BAND_HARMONICS = 25  # the band whose noise level sets the stated bound (band_noise_rms_nm)


@dataclass(frozen=True, slots=True, kw_only=True)
class InertiaFrictionResult:
    """J, B and T_c from sine runs at several amplitudes.

    Attributes
    ----------
    inertia : Estimate
        ``inertia_kg_m2``: J (kg·m²).
    viscous : Estimate
        ``viscous_nm_s_rad``: B (N·m·s/rad).
    coulomb : Estimate
        ``coulomb_nm``: T_c (N·m).
    runs : tuple of SineRun
        The runs fitted.
    method : {"least_squares", "orthogonal"}
        The estimator used.
    harmonics : int
        The harmonics the orthogonal correlation used.
    fit_pct : float
        Share of the periodic torque of the moving samples that ``J·α + B·ω + T_c·sgn(ω)``
        explains (%; constant torques excluded).
    lack_of_fit_rms_nm : float
        RMS of the periodic torque the model leaves unexplained (N·m).
    noise_rms_nm : float
        RMS over the runs of their non-periodic torque (N·m).
    """

    inertia: Estimate  # kg·m²
    viscous: Estimate  # N·m·s/rad
    coulomb: Estimate  # N·m
    runs: tuple[SineRun, ...]
    method: Method
    harmonics: int
    fit_pct: float  # periodic torque of moving samples explained by J·α + B·ω + T_c·sgn(ω)
    lack_of_fit_rms_nm: float
    noise_rms_nm: float


def identify_inertia_friction(
    runs: Sequence[SineRun], *, method: Method = "least_squares", harmonics: int = HARMONICS
) -> InertiaFrictionResult:
    """J, B, T_c from two or more sine runs at distinct amplitudes.

    Parameters
    ----------
    runs : sequence of SineRun
        The reduced runs (:func:`hil.identify.sine_run.analyse_sine_run`), one per amplitude.
    method : {"least_squares", "orthogonal"}
        ``least_squares`` (default): a time-domain fit of ``τ = J·α + B·ω + T_c·sgn ω``
        with α and ω instrumented by their low harmonics. ``orthogonal``: the article's
        correlation per period.
    harmonics : int
        Harmonics of the excitation the orthogonal correlation uses (1: the article's).

    Returns
    -------
    InertiaFrictionResult
        J, B, T_c as :class:`~hil.identify.estimate.Estimate` (delete-one-period jackknife
        standard uncertainties and their degrees of freedom), the runs, the fit's share of the
        periodic torque, its lack of fit and the noise.

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
    # the bound's σ: the noise where the regressors hold their information, not its RMS
    # over all frequencies (band_noise_rms_nm)
    band = [band_noise_rms_nm(r, harmonics=BOUND_BAND_HARMONICS) for r in runs]
    crb = cramer_rao_std(runs, noise_rms_nm=float(np.sqrt(np.mean(np.square(band)))))
    fit_pct, lack_rms = _model_fit(runs, theta)
    names = (("inertia_kg_m2", "kg·m²"), ("viscous_nm_s_rad", "N·m·s/rad"), ("coulomb_nm", "N·m"))
    inertia, viscous, coulomb = (
        Estimate(
            name=name,
            value=float(theta[i]),
            standard_uncertainty=float(u[i]),
            unit=unit,
            dof=float(dof[i]),
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
        harmonics=harmonics,
        fit_pct=fit_pct,
        lack_of_fit_rms_nm=lack_rms,
        noise_rms_nm=noise,
    )


Block = tuple[FloatArray, FloatArray]  # (AᵀA, Aᵀy) of one period


def regressors(run: SineRun, index: int, n_runs: int) -> FloatArray:
    """The regressors of every sample of ``run``: α, ω, sgn ω and one constant per run.

    The constant of each run absorbs torques that do not change within it (gravity at that
    position, offsets).

    Parameters
    ----------
    run : SineRun
        The run.
    index : int
        Its position among the ``n_runs`` runs fitted together.
    n_runs : int
        Number of runs fitted together.

    Returns
    -------
    ndarray, shape (samples, 3 + n_runs)
        Columns α (rad/s²), ω (rad/s), sgn ω, then one column per run: 1 in column
        ``3 + index``, 0 in the others.
    """
    constants = np.zeros((len(run.time_s), n_runs))
    constants[:, index] = 1.0
    return np.column_stack(
        [run.acceleration_rad_s2, run.velocity_rad_s, np.sign(run.velocity_rad_s), constants]
    )


def instruments(run: SineRun, index: int, n_runs: int) -> FloatArray:
    """The regressors with α and ω replaced by their first ``INSTRUMENT_HARMONICS``
    harmonics of the excitation.

    The harmonics (least-squares fit with a constant) are the periodic motion without the
    encoder's quantisation noise, which the derivatives amplify at high frequency
    (instrumental variables).

    Parameters
    ----------
    run, index, n_runs
        As for :func:`regressors`.

    Returns
    -------
    ndarray, shape (samples, 3 + n_runs)
        The columns of :func:`regressors`, the first two smoothed.
    """
    columns = regressors(run, index, n_runs)
    omega_t = 2 * math.pi * run.frequency_hz * run.time_s
    basis = np.column_stack(
        [np.ones_like(omega_t)]
        + [f(k * omega_t) for k in range(1, INSTRUMENT_HARMONICS + 1) for f in (np.cos, np.sin)]
    )
    smooth = basis @ np.linalg.lstsq(basis, columns[:, :2], rcond=None)[0]
    columns[:, :2] = smooth
    return columns


def reversal_taper(smooth_velocity_rad_s: FloatArray, amplitude_rad_s: float) -> FloatArray:
    """Weight of each sample in the instrumented fit: 0 in the reversal band, rising as a
    raised cosine of ``|ω|/V`` to 1 at ``TAPER_END``·V.

    A hard cut at the band's edge would make each moving stretch a rectangular window:
    the sum of the differentiated α's error over a stretch is then the velocity error at
    its two ends, two samples of the encoder's quantisation noise through the
    differentiator, not an average of it. Under a velocity loop that error is not even
    zero-mean: the loop regulates the *measured* velocity, so the true motion carries the
    quantisation error, and the velocity error at the band's edge takes a sign set by the
    direction of acceleration (B +1.2 % with a 19-bit encoder, 0.3 ms lag and a 300 Hz
    velocity filter, +1.7 % without the filter; in open loop the same term is a random
    ±0.8 % per calibration). Weighting by a taper of the instrumented (smooth) velocity
    keeps the instruments band-limited: the edge terms become averages over the taper
    (B within ±0.2 %, the random part ±0.13 %), for 4–6 % more variance than the hard cut.

    Parameters
    ----------
    smooth_velocity_rad_s : array
        The instrumented ω of each sample (rad/s), free of the quantisation noise.
    amplitude_rad_s : float
        V, the run's velocity amplitude (rad/s).

    Returns
    -------
    ndarray
        Weights in [0, 1], one per sample.
    """
    ratio = np.abs(smooth_velocity_rad_s) / amplitude_rad_s
    rise = np.clip((ratio - REVERSAL_BAND) / (TAPER_END - REVERSAL_BAND), 0.0, 1.0)
    return np.asarray(0.5 - 0.5 * np.cos(math.pi * rise), dtype=np.float64)


def _run_blocks(
    run: SineRun, index: int, n_runs: int, method: Method, harmonics: int
) -> list[Block]:
    """The normal equations of each period of ``run``, instrumented: α and ω are correlated
    against their noise-free counterparts (errors in a regressor bias least squares)."""
    if method == "least_squares":
        phi, z = regressors(run, index, n_runs), instruments(run, index, n_runs)
        z *= reversal_taper(z[:, 1], run.velocity_amplitude_rad_s)[:, None]
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
    fit = fit_harmonics(
        omega_t,
        np.column_stack([phi, run.torque_nm[used]]),
        orders=range(1, harmonics + 1),
        trend=polynomial_columns(omega_t, 0),
    )
    components = fit.interleaved()
    return components[:, :3], components[:, 3]


def _jackknife(blocks: list[Block]) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Estimate, delete-one-block jackknife standard uncertainty, and its effective degrees
    of freedom per parameter (:func:`jackknife_dof`)."""
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
    return theta, u, jackknife_dof(normal, [b[0] for b in blocks], size=size)


def jackknife_dof(normal: FloatArray, block_normals: Sequence[FloatArray], *,
                  size: int) -> FloatArray:
    """The effective degrees of freedom of a delete-one-block jackknife variance, per
    parameter (Welch–Satterthwaite).

    Each block adds ``a_i = [N⁻¹·G_i·N⁻ᵀ]_kk`` to the variance of parameter ``k`` (``G_i``
    its normal matrix, white noise), so the jackknife's sum of squared deletions weighs the
    blocks by ``a_i``: ``ν = (n − 1)/n · (Σ a_i)² / Σ a_i²``, ``n − 1`` for equal blocks.
    Periods at two amplitudes are not equal: the larger one's carry about four times the
    information on J and B, and their jackknife about 6.6 degrees of freedom, not 9.
    """
    inverse = np.linalg.inv(normal)
    shares = np.array([np.diag(inverse @ (0.5 * (g + g.T)) @ inverse.T)[:size]
                       for g in block_normals])
    count = len(block_normals)
    return np.asarray((count - 1) / count * np.sum(shares, axis=0) ** 2
                      / np.sum(shares**2, axis=0), dtype=np.float64)


def cramer_rao_std(runs: Sequence[SineRun], *, noise_rms_nm: float) -> FloatArray:
    """Bound on the standard deviation of (J, B, T_c) from the samples the estimator uses.

    ``sqrt(diag(σ²·(ΦᵀΦ)⁻¹))`` over the moving samples of all runs, with the regressors
    Φ of :func:`regressors` (the per-run constants as nuisance parameters).

    Parameters
    ----------
    runs : sequence of SineRun
        The runs fitted together.
    noise_rms_nm : float
        σ, the white torque noise (N·m).

    Returns
    -------
    ndarray, shape (3,)
        The bounds for J (kg·m²), B (N·m·s/rad) and T_c (N·m).
    """
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
    """Spread of the inertias each amplitude shows, in % of their mean.

    Each run gets a J of its own in the fit that measured J, B and T_c (the same samples,
    instruments and reversal band; B, T_c shared): a torque bound to position (cogging,
    cable) commensurate with the sine's travel projects onto α differently at each amplitude
    and shows up here. The article's per-run ``c/(V·2πf)`` is not used: it takes the
    reversals in, where the axis dwells while its loop ramps through the friction, so it
    moved with the loop's stiffness and with friction dynamics (pre-sliding) the model does
    not have, on units whose J was right.

    Parameters
    ----------
    result : InertiaFrictionResult
        The fit whose runs are compared.

    Returns
    -------
    Estimate
        ``inertia_amplitude_spread_pct`` (%): largest minus smallest per-run J over their
        mean; its standard uncertainty by the moving-block jackknife of that spread, blocks
        of ``SPREAD_BLOCK`` consecutive periods of one run (degrees of freedom the periods
        over the block length − 1). Deleting one period at a time stated 0.55 × the spread's
        scatter over noise seeds on the Modbus emulator (sd 0.26 % over 8 seeds against a
        median u of 0.145 %): its low-frequency shaft disturbance (0.5 Hz) makes
        neighbouring periods err alike, and compare flagged a change between two runs of
        one unit.
    """
    n_runs = len(result.runs)
    per_run = [[_with_inertia_per_run(block, index, n_runs)
                for block in _run_blocks(run, index, n_runs, result.method, result.harmonics)]
               for index, run in enumerate(result.runs)]
    blocks = [block for run_blocks in per_run for block in run_blocks]
    normal = np.sum([b[0] for b in blocks], axis=0)
    rhs = np.sum([b[1] for b in blocks], axis=0)

    def spread_pct(n: FloatArray, r: FloatArray) -> float:
        per_run = np.linalg.solve(n, r)[:n_runs]
        return 100 * float(np.ptp(per_run) / per_run.mean())

    length = SPREAD_BLOCK if min(map(len, per_run)) > SPREAD_BLOCK else 1
    deleted = [run_blocks[i:i + length] for run_blocks in per_run
               for i in range(len(run_blocks) - length + 1)]
    try:
        value = spread_pct(normal, rhs)
        leave_out = np.array([spread_pct(normal - sum(b[0] for b in group),
                                         rhs - sum(b[1] for b in group)) for group in deleted])
    except np.linalg.LinAlgError as exc:
        raise IdentificationError("a J per amplitude is not separable from these runs") from exc
    count = len(blocks)
    # the moving-block jackknife (Künsch 1989): (n − l)/l · mean of the squared deviations
    u = math.sqrt((count - length) / length
                  * float(np.mean((leave_out - leave_out.mean()) ** 2)))
    return Estimate(
        name="inertia_amplitude_spread_pct",
        value=value,
        standard_uncertainty=u,
        unit="%",
        dof=float(count / length - 1),
    )


def _with_inertia_per_run(block: Block, index: int, n_runs: int) -> Block:
    """A period's normal equations with the α column (first) split into one per run, this
    period's run in column ``index``: ``Φ' = Φ·M`` gives ``Z'ᵀΦ' = Mᵀ(ZᵀΦ)M``."""
    columns = block[0].shape[1]
    spread = np.zeros((columns, n_runs + columns - 1))
    spread[0, index] = 1.0
    spread[1:, n_runs:] = np.eye(columns - 1)
    return spread.T @ block[0] @ spread, spread.T @ block[1]


def stiffness_corrected_inertia(
    inertia: Estimate, *, stiffness: Estimate, frequency_hz: float
) -> Estimate:
    """J corrected for a position stiffness ``K = dL/dθ`` at the sine's centre.

    A load torque ``L(θ)`` (gravity, cable spring) adds ``K·x`` with ``x = −V/ω·cos ωt`` to
    the torque, in the same quadrature as ``J·α``: the sine sees ``J − K/ω²``.

    Parameters
    ----------
    inertia : Estimate
        J measured by the sine (kg·m²).
    stiffness : Estimate
        K at the sine's centre (N·m/rad; :func:`hil.identify.gravity_cable.load_stiffness`).
    frequency_hz : float
        The sine's frequency (Hz).

    Returns
    -------
    Estimate
        ``J + K/ω²`` with ``u(K)`` a budget line of sensitivity ``1/ω²``.
    """
    omega_sq = (2 * math.pi * frequency_hz) ** 2
    return inertia.with_components(
        Component(
            source="load stiffness dL/dθ at the sines' centre (gravity_cable: m·g·e, φ, "
                   "k_cable)",
            kind="B", standard_uncertainty=stiffness.standard_uncertainty,
            unit=stiffness.unit, sensitivity=1.0 / omega_sq, dof=stiffness.dof,
        ),
        value=inertia.value + stiffness.value / omega_sq,
    )
