"""Stribeck friction (T_s, v_s) from a slow constant-velocity staircase in both directions.

The staircase runs in forward (so a cable's hysteresis loop is dragged to its full
half-width before the first step, whichever way the axis came), forward through
decreasing speeds, turns round beyond its end (so the loop has settled again before the
first slow backward step) and comes back over the *same* positions in the reverse order.
At each speed the settled torque of the two directions is averaged over the positions both
passes covered, so every torque that depends on position only (gravity, cable, cogging,
offset) cancels in the half difference and the friction magnitude remains (with the cable
loop's half-width, which sliding drags along: :mod:`hil.suite.stribeck` takes it out)::

    F(v) = T_c + (T_s − T_c)·exp(−(v/v_s)²) + B·v

``F`` is linear in ``(T_c, T_s − T_c, B)`` for a given ``v_s``: separable least squares
with a bounded 1-D search over ``log v_s``. Speeds at which the axis sticks and slips
(velocity windows that stall or jump) are reported and left out of the fit, not averaged.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

from hil.errors import IdentificationError
from hil.identify.estimate import Estimate
from hil.identify.quantisation import quantisation_step

FloatArray = NDArray[np.float64]
BLOCKS = 8  # sub-windows per matched range, for the Type A scatter
STALL_FRACTION = 0.25  # a velocity window below this fraction of the command has stuck
MIN_STEPS_PER_BLOCK = 10  # encoder steps a sub-window spans at least (its speed resolved)
JUMP_CV = 0.5  # coefficient of variation of window velocities above which motion is jerky
RESOLVED_FRACTION = 0.6  # a clean speed at or below this fraction of v_s is required


@dataclass(frozen=True, slots=True, kw_only=True)
class Staircase:
    """Velocity command of a two-way staircase and where each step lies (sample indices).

    Attributes
    ----------
    command_rad_s : array
        Velocity command (rad/s), one value per sample.
    speeds_rad_s : tuple of float
        The step speeds, fast → slow (rad/s, positive).
    forward_steps : tuple of (int, int)
        ``(start, stop)`` sample indices of each speed's forward step, ``stop`` exclusive.
    backward_steps : tuple of (int, int)
        The same for the backward pass, in the same order of speeds.
    travel_rad : float
        Net forward travel of the staircase, without the turnaround (rad).
    turnaround_rad : float
        Travel out (and back) of the turnaround, as sampled (rad); the run-in before the
        first step is as long.
    """

    command_rad_s: FloatArray
    speeds_rad_s: tuple[float, ...]
    forward_steps: tuple[tuple[int, int], ...]  # (start, stop) per speed, forward pass
    backward_steps: tuple[tuple[int, int], ...]  # same order of speeds, backward pass
    travel_rad: float  # net forward travel of the staircase (without the turnaround)
    turnaround_rad: float  # out and back at the end; the run-in at the start is as long


def staircase(
    speeds_rad_s: Sequence[float],
    *,
    fs_hz: float,
    step_travel_rad: float,
    settle_s: float,
    turnaround_rad: float,
    turnaround_speed_rad_s: float,
) -> Staircase:
    """Build the staircase: a run-in of ``turnaround_rad`` at ``turnaround_speed_rad_s``,
    forward at ``speeds`` (sorted fast → slow), out and back over ``turnaround_rad``,
    backward over the same steps slow → fast.

    Each step lasts ``2·settle_s`` plus the time to cover ``step_travel_rad`` at its speed,
    so the settled parts of the forward and the backward step overlap by ``step_travel_rad``.

    Parameters
    ----------
    speeds_rad_s : sequence of float
        The step speeds (rad/s): at least four, non-zero; signs and order are ignored.
    fs_hz : float
        Command sample rate (Hz).
    step_travel_rad : float
        Travel of each step after settling (rad).
    settle_s : float
        Settling time (s); each step lasts twice this plus its travel time.
    turnaround_rad : float
        Travel beyond the last forward step before turning back, and of the run-in before
        the first (rad).
    turnaround_speed_rad_s : float
        Speed of the turnaround (rad/s).

    Returns
    -------
    Staircase
        The velocity command and the sample ranges of its steps.

    Raises
    ------
    IdentificationError
        Fewer than four speeds, or a zero speed.
    """
    speeds = tuple(sorted((abs(float(v)) for v in speeds_rad_s), reverse=True))
    if len(speeds) < 4 or min(speeds) <= 0:
        raise IdentificationError("need at least four positive staircase speeds")
    lengths = [round((2 * settle_s + step_travel_rad / v) * fs_hz) for v in speeds]
    turn = round(turnaround_rad / turnaround_speed_rad_s * fs_hz)
    pieces: list[FloatArray] = [np.full(turn, turnaround_speed_rad_s)]  # the run-in
    forward, backward = [], []
    index = turn
    for v, n in zip(speeds, lengths, strict=True):
        pieces.append(np.full(n, v))
        forward.append((index, index + n))
        index += n
    pieces += [np.full(turn, turnaround_speed_rad_s), np.full(turn, -turnaround_speed_rad_s)]
    index += 2 * turn
    back_index: dict[int, tuple[int, int]] = {}
    for i in reversed(range(len(speeds))):
        pieces.append(np.full(lengths[i], -speeds[i]))
        back_index[i] = (index, index + lengths[i])
        index += lengths[i]
    backward = [back_index[i] for i in range(len(speeds))]
    command = np.concatenate(pieces)
    travel = float(sum(v * n for v, n in zip(speeds, lengths, strict=True)) / fs_hz)
    return Staircase(
        command_rad_s=command,
        speeds_rad_s=speeds,
        forward_steps=tuple(forward),
        backward_steps=tuple(backward),
        travel_rad=travel,
        turnaround_rad=turn * turnaround_speed_rad_s / fs_hz,
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class SpeedPoint:
    """The friction magnitude at one staircase speed.

    Attributes
    ----------
    speed_rad_s : float
        Mean measured speed of both passes over the matched range (rad/s); the commanded
        speed when no range matched.
    friction_nm : float
        Half difference of the two directions' mean torques (N·m); NaN when no range
        matched.
    friction_u_nm : float
        Its Type A standard uncertainty from the scatter of the sub-window differences
        (N·m); ``inf`` with fewer than two sub-windows.
    load_nm : float
        Half sum: the position-dependent torque averaged over the range (N·m).
    matched_rad : float
        Width of the position range both passes covered after settling (rad).
    stick_slip : bool
        Flagged as stick-slip and left out of the fit: a velocity window stalled, the
        velocity's coefficient of variation reached ``JUMP_CV``, fewer than half the
        sub-windows hold samples of both passes, or the passes' common range spans fewer
        than ``MIN_STEPS_PER_BLOCK`` encoder steps per sub-window (its speed unresolved).
    velocity_cv : float
        Coefficient of variation of the short-window velocities, the larger of the two
        passes (``inf`` where a window stalled or none fit).
    """

    speed_rad_s: float  # mean measured speed of both passes over the matched range
    friction_nm: float  # half difference of the two directions' mean torques
    friction_u_nm: float  # Type A, from the scatter of sub-window differences
    load_nm: float  # half sum: the position-dependent torque averaged over the range
    matched_rad: float  # width of the position range both passes covered after settling
    stick_slip: bool
    velocity_cv: float  # coefficient of variation of short-window velocities


@dataclass(frozen=True, slots=True, kw_only=True)
class StribeckResult:
    """The Stribeck curve fitted through the clean staircase speeds.

    Attributes
    ----------
    static : Estimate
        ``static_friction_nm``: T_s (N·m).
    stribeck_velocity : Estimate
        ``stribeck_velocity_rad_s``: v_s (rad/s).
    coulomb : Estimate
        ``stribeck_coulomb_nm``: T_c (N·m).
    viscous : Estimate
        ``stribeck_viscous_nm_s_rad``: B (N·m·s/rad).
    points : tuple of SpeedPoint
        Every speed, those flagged as stick-slip included.
    residual_rms_nm : float
        RMS of the clean points' friction about the fitted curve (N·m).
    lowest_clean_speed_rad_s : float
        The slowest speed fitted (rad/s).
    """

    static: Estimate  # T_s, N·m
    stribeck_velocity: Estimate  # v_s, rad/s
    coulomb: Estimate  # T_c, N·m
    viscous: Estimate  # B, N·m·s/rad
    points: tuple[SpeedPoint, ...]
    residual_rms_nm: float
    lowest_clean_speed_rad_s: float


def _settled_start(
    time_s: FloatArray, position_rad: FloatArray, speed_rad_s: float, *, settle_s: float,
    window_s: float, tolerance: float,
) -> int:
    """First index after ``settle_s`` from which every window velocity stays within
    ``tolerance`` (relative) of ``speed_rad_s``; the step's end if it never settles."""
    n = len(time_s)
    start = int(np.searchsorted(time_s, time_s[0] + settle_s))
    width = max(int(np.searchsorted(time_s, time_s[0] + window_s)), 2)
    if start + width >= n:
        return n
    v = (position_rad[width:] - position_rad[:-width]) / (time_s[width:] - time_s[:-width])
    bad = np.abs(v - speed_rad_s) > tolerance * abs(speed_rad_s)
    bad[: start] = True
    bad_indices = np.flatnonzero(bad)
    last_bad = int(bad_indices[-1]) if bad_indices.size else -1
    return min(last_bad + 1, n)


def _velocity_windows(time_s: FloatArray, position_rad: FloatArray, window_s: float) -> FloatArray:
    edges = np.arange(time_s[0], time_s[-1], window_s)
    if len(edges) < 3:
        return np.zeros(0)
    p = np.interp(edges, time_s, position_rad)
    return np.diff(p) / window_s


def speed_point(
    forward: tuple[FloatArray, FloatArray, FloatArray],
    backward: tuple[FloatArray, FloatArray, FloatArray],
    *,
    speed_rad_s: float,
    settle_s: float,
    counts_per_window: float,
    resolution_rad: float,
) -> SpeedPoint:
    """Reduce one speed's forward and backward steps to a friction magnitude over the
    position range both passes covered.

    Each step is used from where every velocity window after ``settle_s`` stays within
    20 % of the commanded speed; the matched range is cut into ``BLOCKS`` sub-windows.

    Parameters
    ----------
    forward, backward : tuple of array
        ``(time_s, position_rad, torque_nm)`` of each step (s, rad, N·m).
    speed_rad_s : float
        The commanded speed (rad/s, positive).
    settle_s : float
        Minimum time discarded at the start of each step (s).
    counts_per_window : float
        Encoder steps per velocity window (the window lasts at least 20 ms).
    resolution_rad : float
        The encoder's step (rad).

    Returns
    -------
    SpeedPoint
        Flagged as stick-slip, with NaN friction, when too little of a step settled or no
        sub-window holds samples of both passes; flagged (friction kept) when the common
        range is too short to resolve the speed (see :class:`SpeedPoint`).
    """
    window_s = max(0.02, counts_per_window * resolution_rad / speed_rad_s)
    ranges, cvs = [], []
    for (t, p, _), sign in ((forward, 1.0), (backward, -1.0)):
        start = _settled_start(t, p, sign * speed_rad_s, settle_s=settle_s,
                               window_s=window_s, tolerance=0.2)
        ranges.append((start, len(t)))
        windows = sign * _velocity_windows(t[start:], p[start:], window_s)
        stalled = windows.size > 0 and bool(np.any(windows < STALL_FRACTION * speed_rad_s))
        cv = float(np.std(windows) / speed_rad_s) if windows.size else math.inf
        cvs.append(math.inf if stalled else cv)
    (f0, f1), (b0, b1) = ranges
    pf, pb = forward[1][f0:f1], backward[1][b0:b1]
    if pf.size < 10 or pb.size < 10:
        return SpeedPoint(speed_rad_s=speed_rad_s, friction_nm=math.nan, friction_u_nm=math.inf,
                          load_nm=math.nan, matched_rad=0.0, stick_slip=True, velocity_cv=math.inf)
    low, high = max(pf.min(), pb.min()), min(pf.max(), pb.max())
    edges = np.linspace(low, high, BLOCKS + 1)
    diffs, sums, speeds = [], [], []
    for k in range(BLOCKS):
        means, rates = [], []
        for (t, p, q), (a, b) in ((forward, (f0, f1)), (backward, (b0, b1))):
            mask = (p[a:b] >= edges[k]) & (p[a:b] < edges[k + 1])
            if mask.sum() < 2:
                break
            means.append(float(q[a:b][mask].mean()))
            rates.append(_slope(t[a:b][mask], p[a:b][mask]))
        if len(means) == 2:
            diffs.append((means[0] - means[1]) / 2)
            sums.append((means[0] + means[1]) / 2)
            speeds += rates
    cv = max(cvs)
    # a block inside one encoder step has no speed
    # (passes overlapping by 10 steps, a weak loop at 0.02 rad/s, measured 0 rad/s)
    resolved = high - low >= MIN_STEPS_PER_BLOCK * BLOCKS * resolution_rad
    stick = not (resolved and len(diffs) >= BLOCKS // 2 and cv < JUMP_CV)
    if not diffs:
        return SpeedPoint(speed_rad_s=speed_rad_s, friction_nm=math.nan, friction_u_nm=math.inf,
                          load_nm=math.nan, matched_rad=0.0, stick_slip=True, velocity_cv=cv)
    d = np.array(diffs)
    u = float(d.std(ddof=1) / math.sqrt(d.size)) if d.size > 1 else math.inf
    return SpeedPoint(
        speed_rad_s=float(np.mean(speeds)),
        friction_nm=float(d.mean()),
        friction_u_nm=u,
        load_nm=float(np.mean(sums)),
        matched_rad=float(high - low),
        stick_slip=stick,
        velocity_cv=cv,
    )


def _slope(time_s: FloatArray, position_rad: FloatArray) -> float:
    """A block's speed: the least-squares slope of its encoder positions over time (rad/s,
    magnitude). Its span over its time read a block of N encoder steps 1/N slow (the time
    runs from the first level's first sample to the last level's last, one step more than
    the span), which moved v_s −2.6 % on 2¹⁷ counts; the slope's error is of order 1/N²."""
    centred = time_s - time_s.mean()
    spread = float(centred @ centred)
    return abs(float(centred @ position_rad)) / spread if spread > 0 else 0.0


def stribeck_curve(
    speed_rad_s: FloatArray, *, coulomb_nm: float, static_nm: float,
    stribeck_velocity_rad_s: float, viscous_nm_s_rad: float,
) -> FloatArray:
    """``T_c + (T_s − T_c)·exp(−(v/v_s)²) + B·v`` for ``v ≥ 0``.

    Parameters
    ----------
    speed_rad_s : array
        v (rad/s).
    coulomb_nm, static_nm : float
        T_c and T_s (N·m).
    stribeck_velocity_rad_s : float
        v_s (rad/s).
    viscous_nm_s_rad : float
        B (N·m·s/rad).

    Returns
    -------
    ndarray
        The friction magnitude (N·m) at each speed.
    """
    v = np.asarray(speed_rad_s, dtype=np.float64)
    return (coulomb_nm + (static_nm - coulomb_nm) * np.exp(-((v / stribeck_velocity_rad_s) ** 2))
            + viscous_nm_s_rad * v)


def _linear_fit(v: FloatArray, f: FloatArray, w: FloatArray, vs: float) -> tuple[FloatArray, float]:
    design = np.column_stack([np.ones_like(v), np.exp(-((v / vs) ** 2)), v])
    coef = np.asarray(np.linalg.lstsq(design * w[:, None], f * w, rcond=None)[0], dtype=np.float64)
    residual = (design @ coef - f) * w
    return coef, float(residual @ residual)


def fit_stribeck(points: Sequence[SpeedPoint]) -> StribeckResult:
    """Separable weighted least squares of the Stribeck curve through the clean points.

    Clean points are those not flagged as stick-slip with a finite friction, weighted by
    ``1/u`` (``u`` at least a tenth of the median). The uncertainties are from the fit
    covariance, scaled by ``√(χ²/ν)`` when above one, ``ν`` = clean points − 4.

    Parameters
    ----------
    points : sequence of SpeedPoint
        One per staircase speed (:func:`speed_point`).

    Returns
    -------
    StribeckResult
        T_s, v_s, T_c and B as estimates, the points, the residual and the lowest clean
        speed.

    Raises
    ------
    IdentificationError
        Fewer than six clean speeds, a clean speed not above zero, or the lowest clean
        speed above ``RESOLVED_FRACTION`` × the fitted ``v_s``.
    """
    clean = [p for p in points if not p.stick_slip and math.isfinite(p.friction_nm)]
    if len(clean) < 6:
        raise IdentificationError(
            f"only {len(clean)} of {len(points)} staircase speeds are free of stick-slip; "
            "need six to fit T_c, T_s, v_s and B"
        )
    v = np.array([p.speed_rad_s for p in clean])
    if not np.all(v > 0):
        raise IdentificationError(
            f"staircase speeds must be > 0 rad/s, got {[round(float(x), 6) for x in v]}")
    f = np.array([p.friction_nm for p in clean])
    u = np.array([p.friction_u_nm for p in clean])
    u = np.maximum(u, 0.1 * float(np.median(u)))  # no single point may dominate
    w = 1.0 / u
    lo, hi = math.log(v.min() / 3), math.log(v.max())
    grid = np.linspace(lo, hi, 60)
    costs = [_linear_fit(v, f, w, math.exp(g))[1] for g in grid]
    best = int(np.argmin(costs))
    bracket = (grid[max(best - 1, 0)], grid[min(best + 1, len(grid) - 1)])
    found = minimize_scalar(lambda g: _linear_fit(v, f, w, math.exp(g))[1], bounds=bracket,
                            method="bounded", options={"xatol": 1e-6})
    vs = math.exp(float(found.x))
    coef, cost = _linear_fit(v, f, w, vs)
    tc, delta, b = (float(c) for c in coef)
    if v.min() > RESOLVED_FRACTION * vs:
        stuck = sorted(p.speed_rad_s for p in points if p.stick_slip)
        raise IdentificationError(
            f"lowest clean speed {v.min():.3g} rad/s is above {RESOLVED_FRACTION:g}·v_s "
            f"(fitted v_s = {vs:.3g} rad/s): the Stribeck rise is not resolved"
            + (f"; stick-slip at {[round(s, 4) for s in stuck]} rad/s" if stuck else
               " (extend the staircase to lower speeds)")
        )
    # covariance of (T_c, ΔT, B, v_s) from the weighted Jacobian, scaled by the lack of fit
    e = np.exp(-((v / vs) ** 2))
    jac = np.column_stack([np.ones_like(v), e, v, delta * e * 2 * v**2 / vs**3]) * w[:, None]
    dof = len(v) - 4
    scale = max(cost / dof, 1.0) if dof > 0 else math.inf
    cov = scale * np.linalg.pinv(jac.T @ jac)
    ts_var = cov[0, 0] + cov[1, 1] + 2 * cov[0, 1]
    residual = f - stribeck_curve(v, coulomb_nm=tc, static_nm=tc + delta,
                                  stribeck_velocity_rad_s=vs, viscous_nm_s_rad=b)
    k = float(dof)
    return StribeckResult(
        static=Estimate(name="static_friction_nm", value=tc + delta,
                        standard_uncertainty=math.sqrt(ts_var), unit="N·m", dof=k),
        stribeck_velocity=Estimate(name="stribeck_velocity_rad_s", value=vs,
                                   standard_uncertainty=math.sqrt(cov[3, 3]), unit="rad/s",
                                   dof=k),
        coulomb=Estimate(name="stribeck_coulomb_nm", value=tc,
                         standard_uncertainty=math.sqrt(cov[0, 0]), unit="N·m", dof=k),
        viscous=Estimate(name="stribeck_viscous_nm_s_rad", value=b,
                         standard_uncertainty=math.sqrt(cov[2, 2]), unit="N·m·s/rad", dof=k),
        points=tuple(points),
        residual_rms_nm=float(np.sqrt(np.mean(residual**2))),
        lowest_clean_speed_rad_s=float(v.min()),
    )


def identify_stribeck(
    *,
    time_s: FloatArray,
    position_rad: FloatArray,
    torque_nm: FloatArray,
    stairs: Staircase,
    settle_s: float,
    counts_per_window: float = 20.0,
) -> StribeckResult:
    """Reduce a recorded ``stairs`` run (same sample indexing) and fit the Stribeck curve.

    Velocity windows for the stick-slip test span ``counts_per_window`` encoder steps (the
    step is read off the data) at the commanded speed, so quantisation does not pass for
    stick-slip.

    Parameters
    ----------
    time_s, position_rad, torque_nm : array
        The recorded run, one row per command sample.
    stairs : Staircase
        The commanded staircase (speeds, both directions, sample ranges).
    settle_s : float
        Time discarded at the start of each step (s).
    counts_per_window : float
        Encoder steps per stick-slip test window.

    Returns
    -------
    StribeckResult
        T_s, v_s (and the sliding T_c, B) with uncertainties, the per-speed points (each
        says whether it was flagged as stick-slip and left out), the fit's residual and the
        lowest clean speed.

    Raises
    ------
    IdentificationError
        The recording's length is not the staircase's, or :func:`fit_stribeck` fails.
    """
    if len(time_s) != len(stairs.command_rad_s):
        raise IdentificationError(
            f"recording has {len(time_s)} samples, the staircase {len(stairs.command_rad_s)}"
        )
    resolution_rad = quantisation_step(position_rad)
    points = []
    for v, (a, b), (c, d) in zip(stairs.speeds_rad_s, stairs.forward_steps,
                                 stairs.backward_steps, strict=True):
        points.append(speed_point(
            (time_s[a:b], position_rad[a:b], torque_nm[a:b]),
            (time_s[c:d], position_rad[c:d], torque_nm[c:d]),
            speed_rad_s=v, settle_s=settle_s, counts_per_window=counts_per_window,
            resolution_rad=resolution_rad,
        ))
    return fit_stribeck(points)
