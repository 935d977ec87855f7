"""Cross-coupling between a gimbal's axes: the inner gimbal's products of inertia with its
elevation axis, from the torque the azimuth needs while the elevation swings.

Lagrange's equations of an azimuth ψ carrying an elevation θ (Ekstrand 2001) give the
azimuth's torque

``T = J(θ)·ψ̈ + J'(θ)·θ̇·ψ̇ + d/dt[c(θ)·θ̇] + friction(ψ̇) + k·ψ + …``

with ``J(θ) = J_zenith + ΔJ·cos²θ + P·sin2θ`` (so ``J'(θ) = −ΔJ·sin2θ + 2P·cos2θ``) and the
coupling inertia ``c(θ) = C_level·cosθ + C_vertical·sinθ``: the products of inertia of the
elevation axis with the zenith (``C_level``, the one felt with the elevation level) and with
the line of sight (``C_vertical``). The last term is linear in them:

``d/dt[c·θ̇] = C_level·(cosθ·θ̈ − sinθ·θ̇²) + C_vertical·(sinθ·θ̈ + cosθ·θ̇²)``.

The runs hold the azimuth at a constant speed ±v under its velocity loop (kinetic friction
then a constant whose sign is known; at rest, sticking friction would hold the coupling
torque and the motor would not show it), each pass twice over the same travel: once with
the elevation standing, once with its drive swinging it ``θ₀ + a·sin(2πft)``. What the
azimuth's own position and speed make (cogging, K_t ripple on the friction, the cable's
spring and hysteresis, friction) is the same in both passes at every sample and cancels in
their difference, whatever its law; the difference is the coupling's. Around θ₀ = 0 the
level term is the swing's fundamental and the vertical term its second harmonic, so one
centre separates them. Least squares over every steady sample of the differences, with the
regressors:

- the two coupling columns (the results);
- the two Coriolis columns ``−sin2θ·θ̇·ψ̇`` and ``2cos2θ·θ̇·ψ̇`` (ΔJ and P: their sign flips
  with the azimuth's direction, the coupling's does not);
- an intercept per pass (a slow drift between the two).

The velocity loop lets the azimuth give a little under the coupling torque; that give,
``J·Δψ̈`` (the two passes' ``ψ̈`` apart), is taken out with the azimuth's J from the sine
protocol rather than fitted: the give is the loop's response to the coupling itself, a
few per cent of it, and measured through encoder counts it is mostly quantisation, so a
fitted J traded against the products (their U grew about seventeen-fold on a gimbal
without them).

Torque and every regressor are low-passed alike (parallel filtering, which keeps the fit
unbiased) above the swing's harmonics, where the velocity loop's noise is. Motion comes
from encoder positions by phase-free derivatives
(:func:`hil.identify.kinematics.phase_free_derivatives`). The covariance is Newey–West's
(what is left is coloured). The Cramér–Rao row is the white-noise bound ``σ²·(XᵀX)⁻¹`` of
the same design.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hil.errors import IdentificationError
from hil.identify.estimate import Estimate
from hil.identify.kinematics import phase_free_derivatives, zero_phase_lowpass

FloatArray = NDArray[np.float64]

#: the derivative windows (s): the elevation's large swing, the azimuth's small give (a
#: quintic fit of 0.1 s is exact to 0.1 % at 2 Hz and averages the encoder's counts)
ELEVATION_WINDOW_S = 0.02
AZIMUTH_WINDOW_S = 0.1
#: torque and every regressor are low-passed alike (parallel filtering: the fit stays
#: unbiased) above the swing's harmonics, where the velocity loop's noise is
BAND_HZ = 12.0
#: the design's columns, in order (then one intercept per run)
COLUMNS = ("coupling_level", "coupling_vertical", "coriolis_delta_j", "coriolis_product")


@dataclass(frozen=True, slots=True, kw_only=True)
class CouplingRun:
    """One pass of the azimuth at a constant speed, the elevation swinging, and the same
    pass with the elevation standing (its ``baseline_`` columns, on the same time base
    from the pass's start); ``steady`` marks the samples the fit uses."""

    time_s: FloatArray
    torque_nm: FloatArray  # the azimuth's
    azimuth_rad: FloatArray
    elevation_rad: FloatArray
    baseline_time_s: FloatArray
    baseline_torque_nm: FloatArray
    baseline_azimuth_rad: FloatArray
    steady: NDArray[np.bool_]
    periods: int  # whole swing periods in the steady samples (the jackknife's blocks)


@dataclass(frozen=True, slots=True, kw_only=True)
class CrossCouplingResult:
    """The products of inertia and what the fit took besides them."""

    level: Estimate  # C_level (kg·m²)
    vertical: Estimate  # C_vertical (kg·m²)
    coriolis_delta_j_kg_m2: float  # ΔJ as the Coriolis term shows it
    coriolis_product_kg_m2: float  # P as the Coriolis term shows it
    azimuth_give_rms_nm: float  # J·Δψ̈ taken out: the loop's give under the coupling
    residual_rms_nm: float
    samples: int


def design(run: CouplingRun, *, azimuth_inertia_kg_m2: float
           ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The regressors (:data:`COLUMNS`), the torque difference less the loop's give
    ``J·Δψ̈`` and that give, at the steady samples."""
    theta_rate, theta_accel = phase_free_derivatives(run.elevation_rad, time_s=run.time_s,
                                                     window_s=ELEVATION_WINDOW_S)
    psi_rate, psi_accel = phase_free_derivatives(run.azimuth_rad, time_s=run.time_s,
                                                 window_s=AZIMUTH_WINDOW_S)
    _, standing_accel = phase_free_derivatives(run.baseline_azimuth_rad,
                                               time_s=run.baseline_time_s,
                                               window_s=AZIMUTH_WINDOW_S)
    start = run.time_s[0]
    since = run.baseline_time_s - run.baseline_time_s[0]

    def baseline(values: FloatArray) -> FloatArray:
        return np.asarray(np.interp(run.time_s - start, since, values), dtype=np.float64)

    theta = run.elevation_rad
    cos_t, sin_t = np.cos(theta), np.sin(theta)
    columns = np.column_stack([
        cos_t * theta_accel - sin_t * theta_rate**2,
        sin_t * theta_accel + cos_t * theta_rate**2,
        -np.sin(2 * theta) * theta_rate * psi_rate,
        2 * np.cos(2 * theta) * theta_rate * psi_rate,
        azimuth_inertia_kg_m2 * (psi_accel - baseline(standing_accel)),
        run.torque_nm - baseline(run.baseline_torque_nm),
    ])
    fs_hz = 1.0 / float(np.median(np.diff(run.time_s)))
    whole = ((0, len(run.time_s)),)
    band = np.column_stack([zero_phase_lowpass(column, fs_hz=fs_hz, cutoff_hz=BAND_HZ,
                                               segments=whole) for column in columns.T])
    # kept at 4× the band: more samples of a band-limited signal add no information, and
    # Newey–West's few lags then span the residual's correlation
    step = max(1, int(fs_hz / (4 * BAND_HZ)))
    kept = band[run.steady][::step]
    give = kept[:, -2]
    return kept[:, :-2], kept[:, -1] - give, give


def fit_cross_coupling(runs: Sequence[CouplingRun], *, azimuth_inertia_kg_m2: float,
                       torque_scale: float = 1.0,
                       torque_scale_u: float = 0.0) -> CrossCouplingResult:
    """The products of inertia from ``runs`` (module docstring).

    Parameters
    ----------
    runs : sequence of CouplingRun
        At least two (the azimuth each way), each with steady samples.
    azimuth_inertia_kg_m2 : float
        The azimuth's J in reported-torque units (the loop's give is taken out with it).
    torque_scale, torque_scale_u : float
        Shaft torque per reported torque and its standard uncertainty (1 and 0: the
        results in reported-torque units).

    Returns
    -------
    CrossCouplingResult

    Raises
    ------
    IdentificationError
        Fewer than two runs, or a design that does not separate the coupling columns (the
        elevation did not swing, or every run went the same way).
    """
    if len(runs) < 2:
        raise IdentificationError("the cross-coupling needs the azimuth run both ways")
    blocks = [design(run, azimuth_inertia_kg_m2=azimuth_inertia_kg_m2) for run in runs]
    rows = sum(len(y) for _, y, _ in blocks)
    width = len(COLUMNS) + len(runs)
    x = np.zeros((rows, width))
    y = np.zeros(rows)
    start = 0
    for index, (columns, torque, _) in enumerate(blocks):
        stop = start + len(torque)
        x[start:stop, :len(COLUMNS)] = columns
        x[start:stop, len(COLUMNS) + index] = 1.0
        y[start:stop] = torque
        start = stop
    scale = np.linalg.norm(x, axis=0)
    if np.any(scale == 0) or rows <= width:
        raise IdentificationError("the cross-coupling runs hold no swing of the elevation "
                                  "(or no steady samples)")
    singular = np.linalg.svd(x / scale, compute_uv=False)
    if singular[-1] < 1e-6 * singular[0]:
        raise IdentificationError("the cross-coupling runs do not separate the products of "
                                  "inertia from the azimuth's own terms (the azimuth ran "
                                  "one way only, or the elevation did not swing)")
    beta = _solve(x, y, scale)
    residual = y - x @ beta
    covariance, dof = _jackknife(x, y, scale, _blocks(blocks, runs))
    sigma2 = float(residual @ residual) / (rows - width)
    bound = sigma2 * np.linalg.inv(x.T @ x)

    def estimate(name: str, column: int) -> Estimate:
        value = float(beta[column]) * torque_scale
        u_data = float(np.sqrt(covariance[column, column])) * torque_scale
        u = float(np.hypot(u_data, float(beta[column]) * torque_scale_u))
        return Estimate(name=name, value=value, standard_uncertainty=u, unit="kg·m²",
                        dof=dof, cramer_rao_std=float(np.sqrt(bound[column, column]))
                        * torque_scale)

    return CrossCouplingResult(
        level=estimate("coupling_product_level_kg_m2", 0),
        vertical=estimate("coupling_product_vertical_kg_m2", 1),
        coriolis_delta_j_kg_m2=float(beta[2]) * torque_scale,
        coriolis_product_kg_m2=float(beta[3]) * torque_scale,
        azimuth_give_rms_nm=float(np.sqrt(np.mean(np.concatenate(
            [give for _, _, give in blocks]) ** 2))),
        residual_rms_nm=float(np.sqrt(np.mean(residual**2))),
        samples=rows,
    )


def _solve(x: FloatArray, y: FloatArray, scale: FloatArray) -> FloatArray:
    """Least squares on unit-scaled columns."""
    beta_unit, *_ = np.linalg.lstsq(x / scale, y, rcond=None)
    return np.asarray(beta_unit / scale, dtype=np.float64)


def _blocks(blocks: Sequence[tuple[FloatArray, FloatArray, FloatArray]],
            runs: Sequence[CouplingRun]) -> NDArray[np.int_]:
    """Each row's block: one swing period of one pass (equal runs of its samples)."""
    labels = []
    first = 0
    for (_, torque, _), run in zip(blocks, runs, strict=True):
        count = max(1, run.periods)
        labels.append(first + np.minimum(np.arange(len(torque)) * count // len(torque),
                                         count - 1))
        first += count
    return np.concatenate(labels)


def _jackknife(x: FloatArray, y: FloatArray, scale: FloatArray,
               block: NDArray[np.int_]) -> tuple[FloatArray, float]:
    """Delete-one-block jackknife covariance of the coefficients and its degrees of freedom
    (blocks − 1): a swing period left out at a time, so whatever colour the residual has
    within a period, and whatever the design does not model that varies from one period
    to the next, is in the scatter."""
    labels = np.unique(block)
    leave_out = np.array([_solve(x[block != b], y[block != b], scale) for b in labels])
    spread = leave_out - leave_out.mean(axis=0)
    count = len(labels)
    return (count - 1) / count * spread.T @ spread, float(count - 1)
