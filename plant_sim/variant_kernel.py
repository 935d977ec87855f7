"""The inner loop of :mod:`plant_sim.variant`: one axis, written apart from :mod:`plant_sim.kernel`.

Its choices are not the main simulator's: the integrator (symplectic Euler, Heun or RK4 over
``substeps``), the friction law (a static Stribeck map with a Karnopp stick band, or LuGre
with bristles), the velocity estimator (filtered difference, moving average or a tracking
observer), the PI's structure (parallel or a set-point weight) and a torque-command filter,
the torque applied a fraction of a period after the sample, jittered periods, a round-to-nearest
encoder, harmonics summed directly, and the reported torque taken before or after the
current loop. Parameters are one float vector (``V_*``), harmonics ``(order, amplitude,
phase)`` rows.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

(
    V_J_MOTOR, V_J_LOAD, V_K_SHAFT, V_C_SHAFT,
    V_B_POS, V_B_NEG, V_TC_POS, V_TC_NEG, V_TS, V_VS,
    V_OFFSET, V_MGE, V_GRAV_PHASE, V_K_CABLE, V_CABLE_ZERO,
    V_TAU_I, V_KP, V_KI, V_KT,
    V_STEP_RAD,  # encoder step (0: ideal)
    V_INTEGRATOR,  # 0 symplectic Euler, 1 Heun, 2 RK4
    V_SUBSTEPS,
    V_LUGRE,  # 0 static map with stick band, 1 LuGre
    V_SIGMA0, V_SIGMA1,  # LuGre bristle stiffness and damping
    V_STICK_BAND,  # Karnopp band (rad/s)
    V_ESTIMATOR,  # 0 filtered difference, 1 moving average, 2 tracking observer
    V_ESTIMATOR_HZ, V_MA_TAPS,
    V_SETPOINT_WEIGHT,  # the PI's proportional part acts on b·ω* − ω̂
    V_TORQUE_FILTER_HZ,  # first-order torque-command low-pass (0: none)
    V_APPLY_DELAY,  # fraction of the period before the new command acts
    V_TAP_MEASURED,  # 1: report K_t·measured current (after the current loop)
    V_NOMINAL_DT,
    N_V,
) = range(35)

INTEGRATOR_NAMES = ("symplectic_euler", "heun", "rk4")
_HEUN_NODES = np.array([0.0, 1.0, 0.0, 0.0])
_HEUN_WEIGHTS = np.array([0.5, 0.5, 0.0, 0.0])
_RK4_NODES = np.array([0.0, 0.5, 0.5, 1.0])
_RK4_WEIGHTS = np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6])


@njit(cache=True, fastmath=False)
def _harmonics(theta: float, rows: np.ndarray) -> float:
    total = 0.0
    for r in range(rows.shape[0]):
        total += rows[r, 1] * math.sin(rows[r, 0] * theta + rows[r, 2])
    return total


@njit(cache=True, fastmath=False)
def _stribeck(p: np.ndarray, omega: float, positive: bool) -> float:
    tc = p[V_TC_POS] if positive else p[V_TC_NEG]
    ts = p[V_TS]
    if ts > tc:
        ratio = omega / p[V_VS]
        return float(tc + (ts - tc) * math.exp(-ratio * ratio))
    return float(tc)


@njit(cache=True, fastmath=False)
def _accelerations(p: np.ndarray, cogging: np.ndarray, ripple: np.ndarray, x: np.ndarray,
                   current: float, disturbance: float, sign: float, z: float,
                   stuck: bool) -> tuple[float, float]:
    """Motor and load accelerations at state ``x`` = (θ_m, ω_m, θ_l, ω_l)."""
    theta_m, omega_m, theta_l, omega_l = x[0], x[1], x[2], x[3]
    two_mass = p[V_J_LOAD] > 0.0
    motor = p[V_KT] * current * (1.0 + _harmonics(theta_m, ripple)) - _harmonics(theta_m, cogging)
    out_theta = theta_l if two_mass else theta_m
    load = (p[V_OFFSET] + disturbance + p[V_MGE] * math.cos(out_theta + p[V_GRAV_PHASE])
            + p[V_K_CABLE] * (out_theta - p[V_CABLE_ZERO]))
    b = p[V_B_POS] if omega_m >= 0.0 else p[V_B_NEG]
    if p[V_LUGRE] != 0.0:
        g = _stribeck(p, omega_m, omega_m >= 0.0)
        zdot = omega_m - p[V_SIGMA0] * abs(omega_m) * z / g
        friction = p[V_SIGMA0] * z + p[V_SIGMA1] * zdot + b * omega_m
    else:
        friction = sign * _stribeck(p, omega_m, sign > 0.0) + b * omega_m
    if two_mass:
        shaft = p[V_K_SHAFT] * (theta_m - theta_l) + p[V_C_SHAFT] * (omega_m - omega_l)
        alpha_m = 0.0 if stuck else (motor - shaft - friction) / p[V_J_MOTOR]
        return alpha_m, (shaft - load) / p[V_J_LOAD]
    return (0.0 if stuck else (motor - load - friction) / p[V_J_MOTOR]), 0.0


@njit(cache=True, fastmath=False)
def _net_drive(p: np.ndarray, cogging: np.ndarray, ripple: np.ndarray, x: np.ndarray,
               current: float, disturbance: float) -> float:
    """What the motor side feels besides its friction (for the stick test)."""
    theta_m = x[0]
    motor = p[V_KT] * current * (1.0 + _harmonics(theta_m, ripple)) - _harmonics(theta_m, cogging)
    if p[V_J_LOAD] > 0.0:
        return float(motor - p[V_K_SHAFT] * (theta_m - x[2]) - p[V_C_SHAFT] * (x[1] - x[3]))
    return float(motor - (p[V_OFFSET] + disturbance
                          + p[V_MGE] * math.cos(theta_m + p[V_GRAV_PHASE])
                          + p[V_K_CABLE] * (theta_m - p[V_CABLE_ZERO])))


@njit(cache=True, fastmath=False)
def _current_at(p: np.ndarray, i0: float, target: float, t: float) -> float:
    """The current ``t`` into a step that began at ``i0``, the loop settling on ``target``
    (first order, exact)."""
    if p[V_TAU_I] <= 0.0:
        return target
    return target + (i0 - target) * math.exp(-t / p[V_TAU_I])


@njit(cache=True, fastmath=False)
def _mean_current(p: np.ndarray, i0: float, target: float, h: float) -> float:
    """The current's mean over a step of ``h`` (its exact impulse over ``h``)."""
    if p[V_TAU_I] <= 0.0:
        return target
    return float(target + (i0 - target) * p[V_TAU_I] / h * (1.0 - math.exp(-h / p[V_TAU_I])))


@njit(cache=True, fastmath=False)
def _step(p: np.ndarray, cogging: np.ndarray, ripple: np.ndarray, x: np.ndarray, h: float,
          i0: float, target: float, disturbance: float, z: float) -> float:
    """Advance ``x`` over one physics step (the current settling from ``i0`` on ``target``,
    taken exactly wherever the integrator evaluates it, so that no integrator's step adds
    a lag of its own to the current loop's); returns the bristle state after it."""
    lugre = p[V_LUGRE] != 0.0
    stuck = False
    sign = 1.0 if x[1] >= 0.0 else -1.0
    if not lugre and abs(x[1]) <= p[V_STICK_BAND]:
        drive = _net_drive(p, cogging, ripple, x, i0, disturbance)
        sign = 1.0 if drive >= 0.0 else -1.0
        breakaway = max(p[V_TS], p[V_TC_POS] if sign > 0.0 else p[V_TC_NEG])
        if abs(drive) <= breakaway:
            x[1] = 0.0
            stuck = True
    method = int(p[V_INTEGRATOR])
    before = x[1]
    if method == 0:
        a_m, a_l = _accelerations(p, cogging, ripple, x, _mean_current(p, i0, target, h),
                                  disturbance, sign, z, stuck)
        x[1] += h * a_m
        x[3] += h * a_l
        x[0] += h * x[1]
        x[2] += h * x[3]
    else:
        stages = 2 if method == 1 else 4
        nodes = _HEUN_NODES if method == 1 else _RK4_NODES
        weights = _HEUN_WEIGHTS if method == 1 else _RK4_WEIGHTS
        k = np.zeros((4, 4))
        y = x.copy()
        for s in range(stages):
            if s > 0:
                scale = h * nodes[s]
                for j in range(4):
                    y[j] = x[j] + scale * k[s - 1, j]
            current = _current_at(p, i0, target, nodes[s] * h)
            a_m, a_l = _accelerations(p, cogging, ripple, y, current, disturbance, sign, z, stuck)
            k[s, 0] = y[1]
            k[s, 1] = a_m
            k[s, 2] = y[3]
            k[s, 3] = a_l
        for j in range(4):
            total = 0.0
            for s in range(stages):
                total += weights[s] * k[s, j]
            x[j] += h * total
    if stuck:
        x[1] = 0.0
    elif not lugre and before * x[1] < 0.0:
        x[1] = 0.0  # stopped within the step: the stick test decides at the next one
    if lugre:
        omega = 0.5 * (before + x[1])
        if omega != 0.0:
            rate = p[V_SIGMA0] * abs(omega) / _stribeck(p, omega, omega >= 0.0)
            target = omega / rate
            z = target + (z - target) * math.exp(-rate * h)
    return z


@njit(cache=True, fastmath=False)
def run_variant(p: np.ndarray, cogging: np.ndarray, ripple: np.ndarray, command: np.ndarray,
                periods: np.ndarray, noise: np.ndarray,
                disturbance: np.ndarray, t_max: float, position: np.ndarray,
                velocity: np.ndarray, torque: np.ndarray, current_out: np.ndarray) -> None:
    """Run the velocity loop over ``command`` (one value per period of length ``periods``)."""
    x = np.zeros(4)
    z = 0.0
    current = 0.0
    integrator = 0.0
    v_est = 0.0
    obs_theta = 0.0
    filtered = 0.0
    applied = 0.0
    step = p[V_STEP_RAD]
    dt_nom = p[V_NOMINAL_DT]
    substeps = int(p[V_SUBSTEPS])
    taps = int(p[V_MA_TAPS])
    history = np.zeros(taps + 1)
    n = command.shape[0]
    a_est = 1.0 - math.exp(-2.0 * math.pi * p[V_ESTIMATOR_HZ] * dt_nom)
    a_torque = (1.0 - math.exp(-2.0 * math.pi * p[V_TORQUE_FILTER_HZ] * dt_nom)
                if p[V_TORQUE_FILTER_HZ] > 0.0 else 1.0)
    w_obs = 2.0 * math.pi * p[V_ESTIMATOR_HZ]
    prev = 0.0
    switch = round(p[V_APPLY_DELAY] * substeps)  # sub-steps before a new command acts
    for k in range(n):
        measured = x[0] if step <= 0.0 else round(x[0] / step) * step
        estimator = int(p[V_ESTIMATOR])
        if estimator == 0:
            v_est += a_est * ((measured - prev) / dt_nom - v_est)
        elif estimator == 1:
            for j in range(taps):
                history[j] = history[j + 1]
            history[taps] = measured
            v_est = (history[taps] - history[0]) / (taps * dt_nom) if k >= taps else (
                (measured - history[taps - k]) / (max(k, 1) * dt_nom))
        else:
            obs_theta += v_est * dt_nom
            err = measured - obs_theta
            obs_theta += 2.0 * 0.7 * w_obs * dt_nom * err
            v_est += w_obs * w_obs * dt_nom * err
        prev = measured
        error = command[k] - v_est
        integrator = min(max(integrator + p[V_KI] * error * dt_nom, -t_max), t_max)
        demand = integrator + p[V_KP] * (p[V_SETPOINT_WEIGHT] * command[k] - v_est)
        filtered += a_torque * (demand - filtered)
        reference = min(max(filtered, -t_max), t_max)
        position[k] = measured
        velocity[k] = v_est
        current_out[k] = current  # the measured current (its noise is the torque noise)
        reported = p[V_KT] * current if p[V_TAP_MEASURED] != 0.0 else reference
        torque[k] = reported + noise[k]
        # mechanics over this period: the old command until the new one acts
        dt = periods[k]
        h = dt / substeps
        for s in range(substeps):
            target = (applied if s < switch else reference) / p[V_KT]
            z = _step(p, cogging, ripple, x, h, current, target, disturbance[k], z)
            current = _current_at(p, current, target, h)
        applied = reference
