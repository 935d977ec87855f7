"""Gravity unbalance (m·g·e) and cable stiffness/hysteresis from a slow two-way sweep.

The axis sweeps the travel at constant speed up and back down. In position bins the torque
of the two passes is ``T± = L(θ) ± F`` with ``F`` the sliding friction plus the saturated
cable hysteresis, and the load

    L(θ) = m·g·e·cos(θ + φ) + k_cable·θ + c

(``c``: offset torque, cable zero). The half sum over bins both passes covered cancels ``F``
(and the K_t ripple's effect on it); the joint linear fit in ``[cos θ, sin θ, θ, 1]``
separates gravity from the cable's spring, which a gravity-only fit would absorb into the
``sin θ`` term (``θ ≈ sin θ`` near the horizon; the curvature over a wide travel tells them
apart). Cogging averages within bins; what remains is treated as scatter (Type A from the
fit residual, ``n − 4`` degrees of freedom).

The cable's hysteresis is separated from friction by its *transient*: after the reversal
the friction flips at once, while a Dahl-type hysteresis torque turns over within a short
travel ``s₀``. A slow probe just after a reversal, minus a slow reference pass that had
long settled going the same way over the same positions at the same speed, then follows
``D(s) = c − 2h·exp(−s/s₀)`` in the travel ``s`` since reversal (separable least squares,
1-D search over ``s₀``; ``c`` takes what the two slow passes still differ by). Taking the
reference from the fast full-travel pass instead left the velocity loop's response to
cogging at the two speeds in ``D``: on the azimuth demo its h read +0.28 mN·m (28 %)
noise-free and scattered by 0.26 mN·m over 16 noise seeds; with the slow reference
−0.03 mN·m and 0.09 mN·m (the fit's u 0.09).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

from hil.errors import IdentificationError
from hil.identify.estimate import Estimate, combine_linear
from hil.identify.regression import newey_west_covariance

FloatArray = NDArray[np.float64]
BIN_PATTERN_LAGS = 5  # Bartlett window of the bin fit's covariance (bins)
STANDARD_GRAVITY_M_S2 = 9.80665
REFERENCE_SAMPLES = 4  # reference samples averaged against each probe bin, at least
REFERENCE_LEAD = 1 / 3  # the reference starts this many probe lengths above the probe


@dataclass(frozen=True, slots=True, kw_only=True)
class SweepPlan:
    """Velocity command of the sweep and where its passes lie (sample indices).

    A short run down ends in the slow ``reference`` (the loop settled going down), then the
    full-travel passes ``up`` and ``down``, a short run back up and the slow ``probe`` down
    over the reference's positions: its hysteresis is in transient where the reference's
    had long settled, at the same speed.

    Attributes
    ----------
    command_rad_s : array
        Velocity command (rad/s), one value per sample.
    start_rad : float
        Where the command begins (rad): above the sweep's lower end by the run-in and the
        reference.
    reference, up, down, probe : tuple of int
        ``(start, stop)`` sample indices of each pass, ``stop`` exclusive.
    """

    command_rad_s: FloatArray
    start_rad: float
    reference: tuple[int, int]
    up: tuple[int, int]
    down: tuple[int, int]
    probe: tuple[int, int]


def sweep_plan(
    *, start_rad: float, stop_rad: float, speed_rad_s: float, probe_rad: float,
    probe_speed_rad_s: float, fs_hz: float,
) -> SweepPlan:
    """Down into the slow reference, ``start → stop → start`` at ``speed_rad_s``
    (``start < stop``), up one probe length and down again over it at
    ``probe_speed_rad_s``.

    The reference and the probe run at the same speed over the same positions, so friction,
    cogging as the velocity loop passes it, and the K_t ripple cancel in their difference
    and only the cable's transient stays; one probe length of travel at ``speed_rad_s``
    before the reference saturates the cable's loop going down whatever the start state,
    and the reference begins ``REFERENCE_LEAD`` probe lengths above the probe's reversal so
    that its own slow-down lies outside the probe's positions. The probe is slow so the
    loop settles within a small part of the transient.

    Parameters
    ----------
    start_rad, stop_rad : float
        Ends of the full-travel passes (rad), ``start < stop``.
    speed_rad_s : float
        Speed of the full-travel passes and the short runs (rad/s).
    probe_rad : float
        Length of the probe pass (rad).
    probe_speed_rad_s : float
        Speed of the reference and the probe passes (rad/s).
    fs_hz : float
        Command sample rate (Hz).

    Returns
    -------
    SweepPlan
        The velocity command, where it starts and the sample ranges of its passes.

    Raises
    ------
    IdentificationError
        ``stop_rad − start_rad`` not more than three probe lengths.
    """
    if not stop_rad - start_rad > 3 * probe_rad:
        raise IdentificationError("sweep must be longer than three probe lengths")

    def run(length_rad: float, velocity_rad_s: float) -> FloatArray:
        return np.full(round(length_rad / abs(velocity_rad_s) * fs_hz), velocity_rad_s)

    reference_rad = (1 + REFERENCE_LEAD) * probe_rad
    parts = [
        run(probe_rad, -speed_rad_s),  # run-in: the cable's loop saturated going down
        run(reference_rad, -probe_speed_rad_s),
        run(stop_rad - start_rad, speed_rad_s),
        run(stop_rad - start_rad, -speed_rad_s),
        run(0.75 * probe_rad, speed_rad_s),
        run(0.25 * probe_rad, probe_speed_rad_s),  # slow down, then reverse
        run(probe_rad, -probe_speed_rad_s),
    ]
    edges = np.cumsum([0] + [len(p) for p in parts])
    _, reference, up, down, _, _, probe = (
        (int(a), int(b)) for a, b in itertools.pairwise(edges))
    return SweepPlan(command_rad_s=np.concatenate(parts),
                     start_rad=start_rad + probe_rad + reference_rad,
                     reference=reference, up=up, down=down, probe=probe)


@dataclass(frozen=True, slots=True, kw_only=True)
class GravityCableResult:
    """Gravity unbalance, cable stiffness and hysteresis from a two-way sweep.

    Attributes
    ----------
    mge : Estimate
        ``gravity_mge_nm``: m·g·e (N·m).
    phase : Estimate
        ``gravity_phase_rad``: φ in ``m·g·e·cos(θ + φ)`` (rad).
    stiffness : Estimate
        ``cable_stiffness_nm_rad``: k_cable (N·m/rad).
    offset_nm : float
        The load's constant ``c`` (N·m).
    hysteresis : Estimate
        ``cable_hysteresis_nm``: h, the half width of the cable's loop (N·m).
    hysteresis_angle_rad : float
        s₀, the travel over which the hysteresis turns over (rad).
    hysteresis_angle_u_rad : float
        Standard uncertainty of s₀ from the same fit (rad).
    hysteresis_covariance : float
        Covariance of h and s₀ in that fit (N·m·rad): an h fitted high comes with an s₀
        fitted short.
    friction_nm : float
        Sliding friction at the sweep speed, loop half width − h (N·m).
    loop_half_width_nm : float
        F + h: the mean half difference of the passes over the bins (N·m).
    bins : int
        Position bins both passes covered (the load fit's points).
    residual_rms_nm : float
        RMS residual of the load fit (N·m).
    bin_centres_rad : array
        Centre of each of those bins (rad).
    load_nm : array
        Half sum of the passes per bin (N·m).
    half_difference_nm : array
        Half difference of the passes per bin, F + hysteresis (N·m).
    """

    mge: Estimate  # N·m
    phase: Estimate  # rad
    stiffness: Estimate  # N·m/rad
    offset_nm: float
    hysteresis: Estimate  # N·m, half width of the cable's loop
    hysteresis_angle_rad: float  # s₀
    hysteresis_angle_u_rad: float
    hysteresis_covariance: float  # cov(h, s₀), N·m·rad
    friction_nm: float  # sliding friction at the sweep speed (loop half width − h)
    loop_half_width_nm: float  # F + h
    bins: int
    residual_rms_nm: float
    bin_centres_rad: FloatArray
    load_nm: FloatArray  # half sum per bin
    half_difference_nm: FloatArray  # F + hysteresis per bin


@dataclass(frozen=True, slots=True, kw_only=True)
class CableLoop:
    """The cable's Dahl hysteresis as ``gravity_cable`` measured it.

    Attributes
    ----------
    half_width_nm : float
        h, the loop's half width (N·m).
    half_width_u_nm : float
        Standard uncertainty of h (N·m).
    angle_rad : float
        s₀, the travel over which the loop turns over (rad).
    angle_u_rad : float
        Standard uncertainty of s₀ (rad; 0: taken as exact).
    covariance : float
        Covariance of h and s₀ from their common fit (N·m·rad).
    """

    half_width_nm: float
    half_width_u_nm: float
    angle_rad: float
    angle_u_rad: float = 0.0
    covariance: float = 0.0


def cable_loop_torque_nm(
    position_rad: FloatArray, *, half_width_nm: float, angle_rad: float
) -> FloatArray:
    """The cable's hysteresis torque along a measured path: the Dahl loop this module fits,
    ``dT/ds = (h·sgn(ds) − T)/s₀`` over the travel ``s``, solved exactly per step from a
    relaxed (zero) state.

    Parameters
    ----------
    position_rad : array
        The path (rad), in sample order.
    half_width_nm : float
        h (N·m).
    angle_rad : float
        s₀ (rad, > 0).

    Returns
    -------
    ndarray
        The hysteresis torque at each sample (N·m).
    """
    return half_width_nm * dahl_state(np.ascontiguousarray(position_rad, dtype=float),
                                       angle_rad)


@njit(cache=True)
def dahl_state(position_rad: FloatArray, angle_rad: float) -> FloatArray:  # pragma: no cover
    """The Dahl loop normalised to its half width (−1 … 1), from a relaxed (zero) state:
    each step relaxes it towards the step's direction of travel by ``exp(−|step|/s₀)``; a
    standstill keeps it. (Compiled: a sample-by-sample recursion.)"""
    state = np.empty_like(position_rad)
    z = 0.0
    if position_rad.shape[0]:
        state[0] = 0.0
    for i in range(1, position_rad.shape[0]):
        step = position_rad[i] - position_rad[i - 1]
        if step != 0.0:
            target = 1.0 if step > 0.0 else -1.0
            z = target + (z - target) * math.exp(-abs(step) / angle_rad)
        state[i] = z
    return state


def load_stiffness(
    *, mge: Estimate, phase: Estimate, cable_stiffness: Estimate, position_rad: float
) -> Estimate:
    """``K = dL/dθ = k_cable − m·g·e·sin(θ + φ)`` at ``position_rad``: the spring rate the
    load adds to small motions there.

    Parameters
    ----------
    mge, phase, cable_stiffness : Estimate
        m·g·e (N·m), φ (rad) and k_cable (N·m/rad) of a :class:`GravityCableResult`.
    position_rad : float
        The position θ (rad).

    Returns
    -------
    Estimate
        ``load_stiffness_nm_rad`` (N·m/rad), first-order propagation with the inputs taken
        as independent.
    """
    angle = position_rad + phase.value
    weights = [1.0, -math.sin(angle), -mge.value * math.cos(angle)]
    _, u, dof = combine_linear(
        weights,
        [cable_stiffness.value, mge.value, phase.value],
        [e.standard_uncertainty for e in (cable_stiffness, mge, phase)],
        [e.dof for e in (cable_stiffness, mge, phase)],
    )
    return Estimate(
        name="load_stiffness_nm_rad",
        value=cable_stiffness.value - mge.value * math.sin(angle),
        standard_uncertainty=u,
        unit="N·m/rad",
        dof=dof,
    )


def cable_load_stiffness(*, cable_stiffness: Estimate, mge: Estimate | None) -> Estimate:
    """``K = dL/dθ`` where gravity's phase was not measured (an azimuth, whose profile
    declares no phase): ``k_cable``, gravity's ``−m·g·e·sin(θ + φ)`` somewhere within
    ``±(|m·g·e| + u(m·g·e))``, a rectangular line (none when m·g·e was not measured
    either: the profile declares no gravity).

    Parameters
    ----------
    cable_stiffness : Estimate
        k_cable (N·m/rad).
    mge : Estimate or None
        m·g·e (N·m), when measured.

    Returns
    -------
    Estimate
        ``load_stiffness_nm_rad`` (N·m/rad).
    """
    half = 0.0 if mge is None else abs(mge.value) + mge.standard_uncertainty
    _, u, dof = combine_linear(
        [1.0, 1.0], [cable_stiffness.value, 0.0],
        [cable_stiffness.standard_uncertainty, half / math.sqrt(3)],
        [cable_stiffness.dof, math.inf])
    return Estimate(name="load_stiffness_nm_rad", value=cable_stiffness.value,
                    standard_uncertainty=u, unit="N·m/rad", dof=dof)


def eccentricity_mm(mge: Estimate, *, mass_kg: float) -> Estimate:
    """Centre-of-mass offset ``e = m·g·e / (m·g)``.

    Parameters
    ----------
    mge : Estimate
        m·g·e (N·m).
    mass_kg : float
        The unbalanced mass (kg), taken as exact.

    Returns
    -------
    Estimate
        ``eccentricity_mm`` (mm): ``mge``'s budget, each line scaled.
    """
    return mge.scaled(1000.0 / (mass_kg * STANDARD_GRAVITY_M_S2), name="eccentricity_mm",
                      unit="mm")


def identify_gravity_cable(
    *,
    position_rad: FloatArray,
    torque_nm: FloatArray,
    plan: SweepPlan,
    exclude_rad: float,
    bins: int,
    settle_rad: float,
) -> GravityCableResult:
    """Fit gravity, cable and hysteresis to a recorded ``plan`` (same sample indexing).

    Parameters
    ----------
    position_rad, torque_nm : array
        The recording of ``plan.command_rad_s``: position (rad) and torque (N·m).
    plan : SweepPlan
        The commanded sweep.
    exclude_rad : float
        Travel left out at each end of the passes for the load fit (rad; start-up and
        hysteresis transients).
    bins : int
        Number of position bins for the load fit.
    settle_rad : float
        Travel after the probe's reversal skipped (rad; velocity-loop transient).

    Returns
    -------
    GravityCableResult
        m·g·e, its phase φ, the cable stiffness and the hysteresis half-width h as
        estimates; the offset, the loop's angle s₀, the sliding friction at sweep speed and
        the binned load and half-difference curves.

    Raises
    ------
    IdentificationError
        The recording's length is not the plan's, the usable sweep is under 1 rad, fewer
        than 8 bins hold both passes, or too few samples after the probe's reversal.
    """
    if len(position_rad) != len(plan.command_rad_s):
        raise IdentificationError(
            f"recording has {len(position_rad)} samples, the sweep {len(plan.command_rad_s)}"
        )
    (a0, a1), (b0, b1) = plan.up, plan.down
    (r0, r1), (c0, c1) = plan.reference, plan.probe
    p1, t1 = position_rad[a0:a1], torque_nm[a0:a1]
    p2, t2 = position_rad[b0:b1], torque_nm[b0:b1]
    low = max(p1.min(), p2.min()) + exclude_rad
    high = min(p1.max(), p2.max()) - exclude_rad
    if not high - low > 1.0:
        raise IdentificationError(
            f"usable sweep [{low:.3g}, {high:.3g}] rad is under 1 rad: gravity and cable "
            "cannot be told apart"
        )
    edges = np.linspace(low, high, bins + 1)
    i1 = np.digitize(p1, edges) - 1
    i2 = np.digitize(p2, edges) - 1
    rows, load, half_diff, centres = [], [], [], []
    for k in range(bins):
        m1, m2 = i1 == k, i2 == k
        if m1.sum() < 5 or m2.sum() < 5:
            continue
        regress = [np.array([np.cos(x).mean(), np.sin(x).mean(), x.mean(), 1.0])
                   for x in (p1[m1], p2[m2])]
        rows.append((regress[0] + regress[1]) / 2)
        load.append((t1[m1].mean() + t2[m2].mean()) / 2)
        half_diff.append((t1[m1].mean() - t2[m2].mean()) / 2)
        centres.append((edges[k] + edges[k + 1]) / 2)
    design, y = np.array(rows), np.array(load)
    if len(y) < 8:
        raise IdentificationError(f"only {len(y)} position bins hold both passes; need 8")
    coef = np.linalg.lstsq(design, y, rcond=None)[0]
    residual = y - design @ coef
    dof = len(y) - 4
    # bins alias what cogging leaves into a short-period pattern (about three bins) the
    # smooth load terms cannot follow: autocorrelation-consistent covariance, with a
    # Bartlett window spanning more than one period of it. Over 50 simulated units the
    # RMS of (x − truth)/u was, white: m·g·e 0.30, k 0.53; 3 lags: 0.56, 0.94; 5 lags:
    # 0.82, 1.19; 12 lags: 0.98, 1.54
    cov = newey_west_covariance(design, residual, lags=BIN_PATTERN_LAGS)
    a, b, k_cable, offset = (float(c) for c in coef)
    mge = math.hypot(a, b)
    # m·g·e·cos(θ + φ) = a·cos θ + b·sin θ with a = mge·cos φ, b = −mge·sin φ
    grad_mge = np.array([a / mge, b / mge])
    grad_phase = np.array([b / mge**2, -a / mge**2])
    cov_ab = cov[:2, :2]
    hysteresis, s0, s0_u, covariance = _hysteresis(
        position_rad[r0:r1], torque_nm[r0:r1], position_rad[c0:c1], torque_nm[c0:c1],
        settle_rad=settle_rad)
    loop = float(np.mean(half_diff))
    return GravityCableResult(
        mge=Estimate(name="gravity_mge_nm", value=mge,
                     standard_uncertainty=math.sqrt(grad_mge @ cov_ab @ grad_mge),
                     unit="N·m", dof=dof),
        phase=Estimate(name="gravity_phase_rad", value=math.atan2(-b, a),
                       standard_uncertainty=math.sqrt(grad_phase @ cov_ab @ grad_phase),
                       unit="rad", dof=dof),
        stiffness=Estimate(name="cable_stiffness_nm_rad", value=k_cable,
                           standard_uncertainty=math.sqrt(cov[2, 2]), unit="N·m/rad", dof=dof),
        offset_nm=offset,
        hysteresis=hysteresis,
        hysteresis_angle_rad=s0,
        hysteresis_angle_u_rad=s0_u,
        hysteresis_covariance=covariance,
        friction_nm=loop - hysteresis.value,
        loop_half_width_nm=loop,
        bins=len(y),
        residual_rms_nm=float(np.sqrt(np.mean(residual**2))),
        bin_centres_rad=np.array(centres),
        load_nm=y,
        half_difference_nm=np.array(half_diff),
    )


def _hysteresis(
    p_ref: FloatArray, t_ref: FloatArray, p_probe: FloatArray, t_probe: FloatArray, *,
    settle_rad: float,
) -> tuple[Estimate, float, float, float]:
    """``h`` and ``s₀`` from the probe minus the settled reference in the same direction at
    the same positions and speed: ``2h·exp(−s/s₀)`` (friction, gravity, cable and cogging
    cancel; K_t ripple only scales the small hysteresis term). Returns h, s₀, u(s₀) and
    cov(h, s₀)."""
    reversal = float(p_probe.max())  # the axis overshoots the command's reversal a little
    s = reversal - p_probe  # travel since the reversal (probe runs downwards)
    length = float(s.max())
    edges = np.linspace(settle_rad, length, 41)
    order = np.argsort(p_ref)
    sorted_ref = p_ref[order]
    ss, dd = [], []
    for lo, hi in itertools.pairwise(edges):
        m = (s >= lo) & (s < hi)
        j = order[np.searchsorted(sorted_ref, reversal - hi):np.searchsorted(sorted_ref,
                                                                             reversal - lo)]
        if j.size < REFERENCE_SAMPLES:  # a sparse (polled) reference pass: nearest samples
            centre = np.searchsorted(sorted_ref, reversal - (lo + hi) / 2)
            half = REFERENCE_SAMPLES // 2
            j = order[max(centre - half, 0):centre + half]
        if m.sum() < 3 or j.size < REFERENCE_SAMPLES:
            continue
        ss.append(float(s[m].mean()))
        dd.append(float(t_probe[m].mean()) - float(t_ref[j].mean()))
    if len(ss) < 10:
        raise IdentificationError("too few samples after the reversal for the hysteresis fit")
    s_arr, d_arr = np.array(ss), np.array(dd)

    def fit(s0: float) -> tuple[FloatArray, float]:
        design = np.column_stack([np.ones_like(s_arr), np.exp(-s_arr / s0)])
        coef = np.asarray(np.linalg.lstsq(design, d_arr, rcond=None)[0], dtype=np.float64)
        r = d_arr - design @ coef
        return coef, float(r @ r)

    grid = np.log(np.geomspace(settle_rad / 2, length / 2, 40))
    best = int(np.argmin([fit(math.exp(g))[1] for g in grid]))
    found = minimize_scalar(lambda g: fit(math.exp(g))[1],
                            bounds=(grid[max(best - 1, 0)], grid[min(best + 1, len(grid) - 1)]),
                            method="bounded")
    s0 = math.exp(float(found.x))
    coef, cost = fit(s0)
    amplitude = float(coef[1])
    e = np.exp(-s_arr / s0)
    jac = np.column_stack([np.ones_like(s_arr), e, amplitude * e * s_arr / s0**2])
    dof = len(s_arr) - 3
    cov = cost / dof * np.linalg.pinv(jac.T @ jac)
    estimate = Estimate(name="cable_hysteresis_nm", value=amplitude / 2,
                        standard_uncertainty=math.sqrt(cov[1, 1]) / 2, unit="N·m", dof=dof)
    return estimate, s0, math.sqrt(cov[2, 2]), float(cov[1, 2]) / 2
