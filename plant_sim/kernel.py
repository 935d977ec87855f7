"""The compiled inner loop: drive loops at the control rate, mechanics at ``substeps`` per period.

Everything here is plain float arrays so numba compiles it once (cached on disk). The
Python side (:mod:`plant_sim.model`, :mod:`plant_sim.gimbal`) packs parameters, draws noise
and owns the state. One axis is a tuple of its arrays (:data:`AXIS_ARRAYS`); its drive's
loops run once per period (:func:`control_period`), its mechanics once per physics step
(:func:`mechanics_substep`), so a gimbal's axes step together (:func:`run_gimbal_kernel`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# parameter vector layout
(
    P_J_MOTOR,
    P_J_LOAD,
    P_K_SHAFT,
    P_C_SHAFT,
    P_B_POS,
    P_B_NEG,
    P_TC_POS,
    P_TC_NEG,
    P_TS,
    P_VS,
    P_OFFSET,
    P_MGE,
    P_GRAV_PHASE,
    P_K_CABLE,
    P_CABLE_ZERO,
    P_HYST_NM,
    P_HYST_ANGLE,
    P_TAU_I,
    P_T_MAX,
    P_COUNTS,
    P_VEL_FILTER_HZ,
    P_KP_VEL,
    P_KI_VEL,
    P_KP_POS,
    P_KT,
    P_EXACT_HOLD,
    P_KT_SCALE,
    P_LOCKED,
    P_DELAY,  # firmware: extra control periods between the torque command and the current loop
    P_FEEDFORWARD,  # firmware: 1 adds the torque offset input to the command
    P_COMPENSATION,  # firmware: 1 applies the loaded cogging / K_t ripple table
    P_LF_DECAY,  # low-frequency shaft disturbance: its first-order filter's decay per period
    P_SIGMA0,  # LuGre bristle stiffness (N·m/rad); 0: the static Stribeck map with sticking
    P_SIGMA1,  # LuGre bristle damping (N·m·s/rad)
    N_PARAMS,
) = range(35)

# state vector layout
(
    S_THETA_M,
    S_OMEGA_M,
    S_THETA_L,
    S_OMEGA_L,
    S_TORQUE_ACT,
    S_VEL_EST,
    S_INTEGRATOR,
    S_POS_MEAS_PREV,
    S_HYST,
    S_DELAY_INDEX,  # next slot of the command delay line
    S_DISTURBANCE_LF,  # low-frequency shaft disturbance (N·m), a filtered random walk's state
    S_TORQUE_CMD,  # this period's demand on the current loop (after delay and sensor noise)
    S_DISTURBANCE,  # this period's shaft disturbance (N·m)
    S_ACCEL,  # the carrier's acceleration over the last physics step (rad/s²)
    S_BRISTLE,  # LuGre: the bristles' mean deflection (rad)
    S_EXTERNAL,  # a gimbal's other axis's torque on this carrier, last physics step (N·m)
    N_STATE,
) = range(17)

# rows of the in-loop noise array (one column per control period, drawn by the caller)
(
    L_SHAFT_NM,  # broadband torque disturbance on the shaft, held over the period
    L_SHAFT_LF_DRIVE_NM,  # white input of the low-frequency disturbance's filter
    L_CURRENT_SENSOR_NM,  # current-sensor noise in torque units (K_t·A): the loop follows it
    L_ENCODER_RAD,  # encoder jitter before quantisation
    N_LOOP_NOISE,
) = range(5)

# rows of the output array (one column per control period, sampled at each period's start)
(
    O_POSITION,  # encoder, quantised
    O_VELOCITY,  # the drive's filtered estimate
    O_TORQUE,  # the torque command as reported (+ measurement noise)
    O_CURRENT,  # the drive's measured current
    O_TORQUE_ACTUAL,  # the current loop's torque (ground truth, before K_t ripple)
    O_LOAD_TORQUE,  # a locked rotor's shaft torque sensor (0 when not locked)
    N_OUT,
) = range(7)

# one axis's arrays, in this order (a numba UniTuple of 1-D float arrays)
(
    A_PARAMS,
    A_COGGING,
    A_KT_RIPPLE,
    A_STATE,
    A_COMMAND,
    A_TORQUE_OFFSET,  # the master's torque offset, one per command sample (or empty)
    A_COMP_COGGING,
    A_COMP_RIPPLE,
    A_DELAY_LINE,
    A_TORQUE_NOISE,  # the reported torque's noise, one per command sample
    A_GUARD,  # the motion monitor (G_SIZE values, or empty: none)
    AXIS_ARRAYS,
) = range(12)

# derived constants of one axis (per call: they depend on the physics step)
(
    D_DECAY,
    D_MEAN_FRACTION,
    D_POS_FRACTION,
    D_HALF_H2,
    D_FILTER_GAIN,
    D_TS,
    D_INV_VS,
    D_INV_HYST_ANGLE,
    D_HYST_RATE,
    D_H,
    D_SUBSTEPS,
    N_DERIVED,
) = range(12)

# a gimbal's coupling between its outer (azimuth) and inner (elevation) axes: the outer
# carrier's inertia J(el) = J_BASE + DJ·cos²(el) + P·sin(2el) and the inner gimbal's products
# of inertia with its own axis, c(el) = CC·cos(el) + CS·sin(el) (mass matrix [[J, c], [c, J_el]])
C_J_BASE, C_DJ, C_P, C_CC, C_CS, C_SIZE = range(6)

MODE_TORQUE, MODE_VELOCITY, MODE_POSITION = 0, 1, 2

# the motion monitor's bounds (``guard``): measured position (rad), |velocity| (rad/s)
G_POSITION_MIN, G_POSITION_MAX, G_VELOCITY_MAX, G_SIZE = 0, 1, 2, 3

# what a control period leaves to do: the mechanics, nothing (a clamped rotor), or stop
RUN_MECHANICS, LOCKED_PERIOD, TRIPPED = 0, 1, 2


@njit(cache=True, fastmath=True)
def _quantise(theta: float, counts: float) -> float:
    if counts <= 0.0:
        return theta
    step = 2.0 * math.pi / counts
    return math.floor(theta / step) * step


@njit(cache=True, fastmath=True)
def _periodic(theta: float, table: np.ndarray) -> float:
    """Linear interpolation in a table of one revolution (empty table: 0)."""
    size = table.shape[0] - 1  # last entry repeats the first
    if size <= 0:
        return 0.0
    x = theta * (size / (2.0 * math.pi))
    x -= math.floor(x / size) * size
    i = int(x)
    if i >= size:
        i = size - 1
    frac = x - i
    return float(table[i] + frac * (table[i + 1] - table[i]))


@njit(cache=True, fastmath=True)
def derived_constants(params: np.ndarray, dt_s: float, substeps: int) -> np.ndarray:
    """An axis's constants for a physics step of ``dt_s / substeps``."""
    d = np.zeros(N_DERIVED)
    h = dt_s / substeps
    tau_i = params[P_TAU_I]
    # exact first-order lag under a held command: state decay over one physics step, and the
    # mean of the lagged torque over that step (what the mechanics integrate)
    decay = 0.0 if tau_i <= 0.0 else math.exp(-h / tau_i)
    mean_fraction = 0.0 if tau_i <= 0.0 else tau_i / h * (1.0 - decay)
    d[D_DECAY] = decay
    d[D_MEAN_FRACTION] = mean_fraction
    # the same for position: ∫₀ʰ (h − t)·T(t) dt = h²/2·[T_cmd + pos_fraction·(T_act − T_cmd)];
    # the motor torque is a held input, so its position effect uses the exact double integral
    # (half weight) instead of the symplectic step's full weight: no half-step time advance
    d[D_POS_FRACTION] = 0.0 if tau_i <= 0.0 else 2.0 * tau_i / h * (1.0 - mean_fraction)
    d[D_HALF_H2] = 0.5 * h * h
    fc = params[P_VEL_FILTER_HZ]
    d[D_FILTER_GAIN] = 1.0 if fc <= 0.0 else 1.0 - math.exp(-2.0 * math.pi * fc * dt_s)
    d[D_TS] = max(params[P_TS], params[P_TC_POS], params[P_TC_NEG])
    d[D_INV_VS] = 1.0 / params[P_VS]
    # the loop's relaxation rate per radian (no division by the half width: a subnormal one
    # under fastmath's reciprocal overflowed to inf and froze the axis)
    d[D_INV_HYST_ANGLE] = 1.0 / params[P_HYST_ANGLE]
    d[D_HYST_RATE] = params[P_HYST_NM] * d[D_INV_HYST_ANGLE]
    d[D_H] = h
    d[D_SUBSTEPS] = substeps
    return d


@njit(cache=True, fastmath=True)
def control_period(params: np.ndarray, state: np.ndarray, cogging: np.ndarray,
                   kt_ripple: np.ndarray, command: np.ndarray, offset: np.ndarray,
                   comp_cogging: np.ndarray, comp_ripple: np.ndarray, delay_line: np.ndarray,
                   torque_noise: np.ndarray, guard: np.ndarray, mode: int,
                   loop_noise: np.ndarray, out: np.ndarray, k: int, dt_s: float,
                   derived: np.ndarray) -> int:
    """Period ``k`` of one axis's drive: sensing, its loops, the outputs; the torque demand
    and the shaft disturbance left in the state for the mechanics. Returns
    :data:`RUN_MECHANICS`, :data:`LOCKED_PERIOD` (a clamped rotor: the shaft sensor read,
    no motion) or :data:`TRIPPED` (the monitor tripped: this period is the last one run).
    The arrays are one axis's (:data:`AXIS_ARRAYS`), passed one by one: taking them out of
    the tuple here would count references every period, four times the kernel's time."""
    kt = params[P_KT]
    t_max = params[P_T_MAX]
    disturbance = 0.0
    sensor_nm = 0.0
    encoder_rad = 0.0
    if loop_noise.shape[1] > 0:
        disturbance_lf = (params[P_LF_DECAY] * state[S_DISTURBANCE_LF]
                          + loop_noise[L_SHAFT_LF_DRIVE_NM, k])
        state[S_DISTURBANCE_LF] = disturbance_lf
        disturbance = loop_noise[L_SHAFT_NM, k] + disturbance_lf
        sensor_nm = loop_noise[L_CURRENT_SENSOR_NM, k]
        encoder_rad = loop_noise[L_ENCODER_RAD, k]
    state[S_DISTURBANCE] = disturbance
    theta_m = state[S_THETA_M]
    torque_act = state[S_TORQUE_ACT]
    # --- sensing and the drive's loops ---
    pos_meas = _quantise(theta_m + encoder_rad, params[P_COUNTS])
    vel_est = state[S_VEL_EST]
    vel_est += derived[D_FILTER_GAIN] * ((pos_meas - state[S_POS_MEAS_PREV]) / dt_s - vel_est)
    state[S_VEL_EST] = vel_est
    state[S_POS_MEAS_PREV] = pos_meas
    command_k = command[k]
    if mode == MODE_TORQUE:
        torque_cmd = command_k
    else:
        velocity_mode = mode == MODE_VELOCITY
        vel_ref = command_k if velocity_mode else params[P_KP_POS] * (command_k - pos_meas)
        error = vel_ref - vel_est
        integrator = state[S_INTEGRATOR] + params[P_KI_VEL] * error * dt_s
        integrator = min(max(integrator, -t_max), t_max)  # anti-windup clamp
        state[S_INTEGRATOR] = integrator
        torque_cmd = params[P_KP_VEL] * error + integrator
    if params[P_FEEDFORWARD] != 0.0 and offset.shape[0] > 0:
        torque_cmd += offset[k]
    if params[P_COMPENSATION] != 0.0:
        torque_cmd += _periodic(pos_meas, comp_cogging)
        torque_cmd /= 1.0 + _periodic(pos_meas, comp_ripple)
    torque_cmd = min(max(torque_cmd, -t_max), t_max)
    out[O_POSITION, k] = pos_meas
    out[O_VELOCITY, k] = vel_est
    out[O_TORQUE, k] = torque_cmd + torque_noise[k]
    out[O_CURRENT, k] = (torque_act + sensor_nm) / kt  # the drive's measured current
    out[O_TORQUE_ACTUAL, k] = torque_act
    out[O_LOAD_TORQUE, k] = 0.0
    if guard.shape[0] >= G_SIZE and (
            pos_meas < guard[G_POSITION_MIN] or pos_meas > guard[G_POSITION_MAX]
            or abs(vel_est) > guard[G_VELOCITY_MAX]):
        return TRIPPED
    delay = int(params[P_DELAY])
    if delay > 0:  # the current loop gets the command of `delay` periods ago
        slot = int(state[S_DELAY_INDEX])
        held_cmd = delay_line[slot]
        delay_line[slot] = torque_cmd
        state[S_DELAY_INDEX] = slot + 1 if slot + 1 < delay else 0
        torque_cmd = held_cmd
    # the current loop drives the measured current (true + sensor noise) to the demand
    torque_cmd -= sensor_nm
    state[S_TORQUE_CMD] = torque_cmd
    if params[P_LOCKED] != 0.0:
        # the clamp's torque sensor holds everything acting on the (still) rotor
        held = params[P_KT_SCALE] * torque_act * (1.0 + _periodic(theta_m, kt_ripple))
        held -= _periodic(theta_m, cogging) + params[P_OFFSET] + state[S_HYST]
        held -= params[P_MGE] * math.cos(theta_m + params[P_GRAV_PHASE]) + disturbance
        held -= params[P_K_CABLE] * (theta_m - params[P_CABLE_ZERO]) + state[S_EXTERNAL]
        out[O_LOAD_TORQUE, k] = held
        decay = derived[D_DECAY] ** int(derived[D_SUBSTEPS])
        state[S_TORQUE_ACT] = torque_cmd + decay * (torque_act - torque_cmd)
        return LOCKED_PERIOD
    return RUN_MECHANICS


@njit(cache=True, fastmath=True)
def mechanics_substep(params: np.ndarray, state: np.ndarray, cogging: np.ndarray,
                      kt_ripple: np.ndarray, derived: np.ndarray, j_carrier: float,
                      external_nm: float) -> None:
    """One physics step of one axis under its period's torque demand. ``j_carrier`` is the
    inertia of the part that carries the load torques (the load of a two-mass axis, else
    the motor); ``external_nm`` a further load torque on it (a gimbal's other axis)."""
    two_mass = params[P_J_LOAD] > 0.0
    h = derived[D_H]
    inv_j_m = 1.0 / (params[P_J_MOTOR] if two_mass else j_carrier)
    theta_m = state[S_THETA_M]
    omega_m = state[S_OMEGA_M]
    theta_l = state[S_THETA_L]
    omega_l = state[S_OMEGA_L]
    torque_act = state[S_TORQUE_ACT]
    torque_cmd = state[S_TORQUE_CMD]
    hyst = state[S_HYST]
    ts = derived[D_TS]
    mean_fraction = derived[D_MEAN_FRACTION]
    half_h2 = derived[D_HALF_H2]
    exact_hold = params[P_EXACT_HOLD] != 0.0
    carrier_before = omega_l if two_mass else omega_m

    t_applied = torque_cmd + mean_fraction * (torque_act - torque_cmd)
    t_position = torque_cmd + derived[D_POS_FRACTION] * (torque_act - torque_cmd)
    state[S_TORQUE_ACT] = torque_cmd + derived[D_DECAY] * (torque_act - torque_cmd)
    ripple_gain = params[P_KT_SCALE] * (1.0 + _periodic(theta_m, kt_ripple))
    # exact hold: the drive's torque is held over the step, so its position effect is h²/2
    # (the symplectic step gives h²), plus the current loop's lag within it
    lag_shift = 0.0
    if exact_hold:
        lag_shift = half_h2 * inv_j_m * ripple_gain * (t_position - t_applied)
    t_motor = t_applied * ripple_gain
    t_motor -= _periodic(theta_m, cogging)
    theta_out = theta_l if two_mass else theta_m
    omega_out = omega_l if two_mass else omega_m
    t_load = params[P_OFFSET] + state[S_DISTURBANCE] + external_nm
    mge = params[P_MGE]
    if mge != 0.0:
        t_load += mge * math.cos(theta_out + params[P_GRAV_PHASE])
    t_load += params[P_K_CABLE] * (theta_out - params[P_CABLE_ZERO])
    if params[P_HYST_NM] > 0.0:
        inv_angle = derived[D_INV_HYST_ANGLE]
        hyst += h * (derived[D_HYST_RATE] * omega_out - abs(omega_out) * hyst * inv_angle)
        t_load += hyst
        state[S_HYST] = hyst
    if two_mass:
        t_shaft = params[P_K_SHAFT] * (theta_m - theta_l) + params[P_C_SHAFT] * (omega_m - omega_l)
        omega_l += h * (t_shaft - t_load) / j_carrier
        theta_l += h * omega_l
        state[S_OMEGA_L] = omega_l
        state[S_THETA_L] = theta_l
        state[S_ACCEL] = (omega_l - carrier_before) / h
        t_drive = t_motor - t_shaft
    else:
        t_drive = t_motor - t_load
    if params[P_SIGMA0] > 0.0:
        state[S_BRISTLE], t_fric = lugre_friction(params, state[S_BRISTLE], omega_m, h,
                                                  derived[D_INV_VS])
        omega_m += h * (t_drive - t_fric) * inv_j_m
    # friction with sticking: at rest until |t_drive| exceeds the breakaway torque
    elif omega_m == 0.0:
        if abs(t_drive) <= ts:
            if not two_mass:
                state[S_ACCEL] = 0.0
            return
        t_fric = math.copysign(ts, t_drive)
        omega_m = h * (t_drive - t_fric) * inv_j_m
    else:
        if omega_m > 0.0:
            tc = params[P_TC_POS]
            b = params[P_B_POS]
        else:
            tc = params[P_TC_NEG]
            b = params[P_B_NEG]
        if ts > tc:
            ratio = omega_m * derived[D_INV_VS]
            tc += (ts - tc) * math.exp(-ratio * ratio)
        t_fric = math.copysign(tc, omega_m) + b * omega_m
        omega_new = omega_m + h * (t_drive - t_fric) * inv_j_m
        # through zero: stick only if friction can hold the applied torque there
        crossed = omega_new * omega_m < 0.0
        omega_m = 0.0 if crossed and abs(t_drive) <= ts else omega_new
    theta_m += h * omega_m
    if exact_hold and omega_m != 0.0:
        # −h²/2 of the acceleration the held torque leaves after friction and the load (zero
        # at constant speed); the shaft spring stays symplectic
        theta_m += lag_shift - half_h2 * inv_j_m * (t_motor - t_load - t_fric)
    state[S_THETA_M] = theta_m
    state[S_OMEGA_M] = omega_m
    if not two_mass:
        state[S_ACCEL] = (omega_m - carrier_before) / h


@njit(cache=True, fastmath=True)
def lugre_friction(params: np.ndarray, bristle_rad: float, omega_m: float, h: float,
                   inv_vs: float) -> tuple[float, float]:
    """One physics step of LuGre friction (Canudas de Wit 1995): the bristles deflect as
    ``ż = ω − σ0·|ω|·z/g(ω)`` (``g`` the Stribeck map, so the steady state is that map)
    and push with ``σ0·z + σ1·ż + B·ω``; no sticking, pre-sliding instead. The deflection is
    advanced exactly for the step's ω (its relaxation is stiff at speed). Returns the new
    deflection and the friction torque."""
    if omega_m >= 0.0:
        tc = params[P_TC_POS]
        b = params[P_B_POS]
    else:
        tc = params[P_TC_NEG]
        b = params[P_B_NEG]
    g = tc
    if params[P_TS] > tc:
        ratio = omega_m * inv_vs
        g += (params[P_TS] - tc) * math.exp(-ratio * ratio)
    sigma0 = params[P_SIGMA0]
    z_new = bristle_rad
    if omega_m != 0.0:
        rate = sigma0 * abs(omega_m) / g
        steady = omega_m / rate
        z_new = steady + (bristle_rad - steady) * math.exp(-rate * h)
    return z_new, sigma0 * z_new + params[P_SIGMA1] * (z_new - bristle_rad) / h + b * omega_m


@njit(cache=True, fastmath=True)
def carrier_inertia(params: np.ndarray) -> float:
    """The inertia of the part that carries an axis's load torques."""
    return float(params[P_J_LOAD] if params[P_J_LOAD] > 0.0 else params[P_J_MOTOR])


@njit(cache=True, fastmath=True)
def run_kernel(
    params: np.ndarray,
    cogging: np.ndarray,
    kt_ripple: np.ndarray,
    state: np.ndarray,
    mode: int,
    command: np.ndarray,
    torque_offset: np.ndarray,
    comp_cogging: np.ndarray,
    comp_ripple: np.ndarray,
    delay_line: np.ndarray,
    torque_noise: np.ndarray,
    loop_noise: np.ndarray,
    dt_s: float,
    substeps: int,
    out_position: np.ndarray,
    out_velocity: np.ndarray,
    out_torque: np.ndarray,
    out_current: np.ndarray,
    out_torque_actual: np.ndarray,
    out_load_torque: np.ndarray,
    guard: np.ndarray,
) -> int:
    """Advance one axis ``len(command)`` control periods. Outputs are sampled at each period
    start.

    The physics of :func:`control_period` and :func:`mechanics_substep` written out once
    more, the state in locals: one axis runs four times as fast as through those helpers
    (numba counts references on every array a call takes). ``tests/test_gimbal_plant.py``
    holds the two equal: a gimbal without coupling gives each axis this kernel's recording.

    ``guard`` (``G_SIZE`` values, or empty: none) is the drive's motion monitor: the first
    period whose encoder position leaves ``[G_POSITION_MIN, G_POSITION_MAX]`` or whose
    velocity estimate exceeds ``G_VELOCITY_MAX`` in size is the last one run (its outputs
    written, no mechanics after it). Returns the number of periods run.

    ``out_load_torque`` is the shaft torque sensor of a locked rotor (0 when not locked).
    Firmware: ``torque_offset`` (one per command sample, or empty) is added to the torque
    command when ``P_FEEDFORWARD`` is set; with ``P_COMPENSATION`` set the command gets
    ``comp_cogging(θ̂)`` added and is divided by ``1 + comp_ripple(θ̂)`` (θ̂ the encoder);
    the reported torque is that command; ``delay_line`` (``P_DELAY`` slots, state across
    calls) holds it back that many control periods before the current loop.

    ``loop_noise`` (``N_LOOP_NOISE`` rows, one column per period, or zero columns: none) is
    the noise a real axis feeds back: a shaft torque disturbance (broadband + a first-order
    low-pass of ``L_SHAFT_LF_DRIVE_NM``), current-sensor noise (the current loop regulates
    the measured current, so the torque it makes is the demand minus that noise; the
    reported current is the measured one) and encoder jitter ahead of the quantiser, which
    the velocity estimate differentiates and the velocity loop feeds back.
    """
    j_m = params[P_J_MOTOR]
    j_l = params[P_J_LOAD]
    two_mass = j_l > 0.0
    k_s = params[P_K_SHAFT]
    c_s = params[P_C_SHAFT]
    t_max = params[P_T_MAX]
    kt = params[P_KT]
    counts = params[P_COUNTS]
    h = dt_s / substeps
    tau_i = params[P_TAU_I]
    # exact first-order lag under a held command: state decay over one physics step, and the
    # mean of the lagged torque over that step (what the mechanics integrate)
    decay = 0.0 if tau_i <= 0.0 else math.exp(-h / tau_i)
    mean_fraction = 0.0 if tau_i <= 0.0 else tau_i / h * (1.0 - decay)
    # the same for position: ∫₀ʰ (h − t)·T(t) dt = h²/2·[T_cmd + pos_fraction·(T_act − T_cmd)];
    # the motor torque is a held input, so its position effect uses the exact double integral
    # (half weight) instead of the symplectic step's full weight: no half-step time advance
    pos_fraction = 0.0 if tau_i <= 0.0 else 2.0 * tau_i / h * (1.0 - mean_fraction)
    exact_hold = params[P_EXACT_HOLD] != 0.0
    half_h2 = 0.5 * h * h
    kt_scale = params[P_KT_SCALE]  # true K_t over the nominal the drive converts with
    locked = params[P_LOCKED] != 0.0
    fc = params[P_VEL_FILTER_HZ]
    filter_gain = 1.0 if fc <= 0.0 else 1.0 - math.exp(-2.0 * math.pi * fc * dt_s)
    hyst_nm = params[P_HYST_NM]
    # the loop's relaxation rate per radian (no division by hyst_nm: a subnormal half
    # width under fastmath's reciprocal overflowed to inf and froze the axis)
    inv_hyst_angle = 1.0 / params[P_HYST_ANGLE]
    hyst_rate = hyst_nm * inv_hyst_angle
    ts = max(params[P_TS], params[P_TC_POS], params[P_TC_NEG])
    inv_vs = 1.0 / params[P_VS]
    inv_j_m = 1.0 / j_m
    mge = params[P_MGE]
    grav_phase = params[P_GRAV_PHASE]
    delay = int(params[P_DELAY])
    feedforward = params[P_FEEDFORWARD] != 0.0 and torque_offset.shape[0] > 0
    compensate = params[P_COMPENSATION] != 0.0

    theta_m = state[S_THETA_M]
    omega_m = state[S_OMEGA_M]
    theta_l = state[S_THETA_L]
    omega_l = state[S_OMEGA_L]
    torque_act = state[S_TORQUE_ACT]
    vel_est = state[S_VEL_EST]
    integrator = state[S_INTEGRATOR]
    pos_prev = state[S_POS_MEAS_PREV]
    hyst = state[S_HYST]
    bristle = state[S_BRISTLE]
    lugre = params[P_SIGMA0] > 0.0
    slot = int(state[S_DELAY_INDEX])
    noisy = loop_noise.shape[1] > 0
    lf_decay = params[P_LF_DECAY]
    disturbance_lf = state[S_DISTURBANCE_LF]
    disturbance = 0.0
    sensor_nm = 0.0
    encoder_rad = 0.0
    guarded = guard.shape[0] >= G_SIZE
    done = command.shape[0]

    for k in range(command.shape[0]):
        if noisy:
            disturbance_lf = lf_decay * disturbance_lf + loop_noise[L_SHAFT_LF_DRIVE_NM, k]
            disturbance = loop_noise[L_SHAFT_NM, k] + disturbance_lf
            sensor_nm = loop_noise[L_CURRENT_SENSOR_NM, k]
            encoder_rad = loop_noise[L_ENCODER_RAD, k]
        # --- sensing and the drive's loops, once per control period ---
        pos_meas = _quantise(theta_m + encoder_rad, counts)
        vel_est += filter_gain * ((pos_meas - pos_prev) / dt_s - vel_est)
        pos_prev = pos_meas
        if mode == MODE_TORQUE:
            torque_cmd = command[k]
        else:
            if mode == MODE_VELOCITY:
                vel_ref = command[k]
            else:
                vel_ref = params[P_KP_POS] * (command[k] - pos_meas)
            error = vel_ref - vel_est
            integrator += params[P_KI_VEL] * error * dt_s
            integrator = min(max(integrator, -t_max), t_max)  # anti-windup clamp
            torque_cmd = params[P_KP_VEL] * error + integrator
        if feedforward:
            torque_cmd += torque_offset[k]
        if compensate:
            torque_cmd += _periodic(pos_meas, comp_cogging)
            torque_cmd /= 1.0 + _periodic(pos_meas, comp_ripple)
        torque_cmd = min(max(torque_cmd, -t_max), t_max)
        out_position[k] = pos_meas
        out_velocity[k] = vel_est
        out_torque[k] = torque_cmd + torque_noise[k]
        out_current[k] = (torque_act + sensor_nm) / kt  # the drive's measured current
        out_torque_actual[k] = torque_act
        if guarded and (pos_meas < guard[G_POSITION_MIN] or pos_meas > guard[G_POSITION_MAX]
                        or abs(vel_est) > guard[G_VELOCITY_MAX]):
            out_load_torque[k] = 0.0  # the monitor trips: this period is the last one run
            done = k + 1
            break
        if delay > 0:  # the current loop gets the command of `delay` periods ago
            held_cmd = delay_line[slot]
            delay_line[slot] = torque_cmd
            slot = slot + 1 if slot + 1 < delay else 0
            torque_cmd = held_cmd
        # the current loop drives the measured current (true + sensor noise) to the demand
        torque_cmd -= sensor_nm
        if locked:
            # the clamp's torque sensor holds everything acting on the (still) rotor
            held = kt_scale * torque_act * (1.0 + _periodic(theta_m, kt_ripple))
            held -= _periodic(theta_m, cogging) + params[P_OFFSET] + hyst
            held -= mge * math.cos(theta_m + grav_phase) + disturbance
            held -= params[P_K_CABLE] * (theta_m - params[P_CABLE_ZERO])
            out_load_torque[k] = held
            torque_act = torque_cmd + decay**substeps * (torque_act - torque_cmd)
            continue
        out_load_torque[k] = 0.0

        # --- mechanics ---
        for _ in range(substeps):
            t_applied = torque_cmd + mean_fraction * (torque_act - torque_cmd)
            t_position = torque_cmd + pos_fraction * (torque_act - torque_cmd)
            torque_act = torque_cmd + decay * (torque_act - torque_cmd)
            ripple_gain = kt_scale * (1.0 + _periodic(theta_m, kt_ripple))
            # exact hold: the drive's torque is held over the step, so its position effect
            # is h²/2 (the symplectic step gives h²), plus the current loop's lag within it
            lag_shift = 0.0
            if exact_hold:
                lag_shift = half_h2 * inv_j_m * ripple_gain * (t_position - t_applied)
            t_motor = t_applied * ripple_gain
            t_motor -= _periodic(theta_m, cogging)
            theta_out = theta_l if two_mass else theta_m
            omega_out = omega_l if two_mass else omega_m
            t_load = params[P_OFFSET] + disturbance
            if mge != 0.0:
                t_load += mge * math.cos(theta_out + grav_phase)
            t_load += params[P_K_CABLE] * (theta_out - params[P_CABLE_ZERO])
            if hyst_nm > 0.0:
                hyst += h * (hyst_rate * omega_out - abs(omega_out) * hyst * inv_hyst_angle)
                t_load += hyst
            if two_mass:
                t_shaft = k_s * (theta_m - theta_l) + c_s * (omega_m - omega_l)
                omega_l += h * (t_shaft - t_load) / j_l
                theta_l += h * omega_l
                t_drive = t_motor - t_shaft
            else:
                t_drive = t_motor - t_load
            if lugre:
                bristle, t_fric = lugre_friction(params, bristle, omega_m, h, inv_vs)
                omega_m += h * (t_drive - t_fric) * inv_j_m
            # friction with sticking: at rest until |t_drive| exceeds the breakaway torque
            elif omega_m == 0.0:
                if abs(t_drive) <= ts:
                    continue
                t_fric = math.copysign(ts, t_drive)
                omega_m = h * (t_drive - t_fric) * inv_j_m
            else:
                if omega_m > 0.0:
                    tc = params[P_TC_POS]
                    b = params[P_B_POS]
                else:
                    tc = params[P_TC_NEG]
                    b = params[P_B_NEG]
                if ts > tc:
                    ratio = omega_m * inv_vs
                    tc += (ts - tc) * math.exp(-ratio * ratio)
                t_fric = math.copysign(tc, omega_m) + b * omega_m
                omega_new = omega_m + h * (t_drive - t_fric) * inv_j_m
                # through zero: stick only if friction can hold the applied torque there
                crossed = omega_new * omega_m < 0.0
                omega_m = 0.0 if crossed and abs(t_drive) <= ts else omega_new
            theta_m += h * omega_m
            if exact_hold and omega_m != 0.0:
                # −h²/2 of the acceleration the held torque leaves after friction and the
                # load (zero at constant speed); the shaft spring stays symplectic
                theta_m += lag_shift - half_h2 * inv_j_m * (t_motor - t_load - t_fric)

    state[S_THETA_M] = theta_m
    state[S_OMEGA_M] = omega_m
    state[S_THETA_L] = theta_l
    state[S_OMEGA_L] = omega_l
    state[S_TORQUE_ACT] = torque_act
    state[S_VEL_EST] = vel_est
    state[S_INTEGRATOR] = integrator
    state[S_POS_MEAS_PREV] = pos_prev
    state[S_HYST] = hyst
    state[S_DELAY_INDEX] = slot
    state[S_DISTURBANCE_LF] = disturbance_lf
    state[S_BRISTLE] = bristle
    return int(done)


@njit(cache=True, fastmath=True)
def run_gimbal_kernel(outer: tuple[np.ndarray, ...], outer_mode: int,
                      outer_noise: np.ndarray, outer_out: np.ndarray,
                      inner: tuple[np.ndarray, ...], inner_mode: int,
                      inner_noise: np.ndarray, inner_out: np.ndarray,
                      coupling: np.ndarray, dt_s: float, substeps: int) -> int:
    """Advance a two-axis gimbal (``outer`` carries ``inner``) ``len(command)`` periods;
    returns the number run (either axis's monitor stops both).

    Mass matrix of the carriers (outer ψ, inner θ): ``[[J(θ), c(θ)], [c(θ), J_el]]`` with
    ``J(θ) = J_BASE + DJ·cos²θ + P·sin2θ`` and ``c(θ) = CC·cosθ + CS·sinθ`` (Lagrange):
    ``J·ψ̈ + c·θ̈ + J'·θ̇·ψ̇ + c'·θ̇² = T_ψ`` and ``c·ψ̈ + J_el·θ̈ − ½·J'·ψ̇² = T_θ``. Each
    axis takes the other's terms as a load torque, with the other's acceleration of the
    step before (stable while c² < J·J_el, which a positive-definite mass matrix is).
    """
    (p_out, cog_out, rip_out, s_out, cmd_out, off_out, ccog_out, crip_out, dl_out, tn_out,
     g_out) = outer
    (p_in, cog_in, rip_in, s_in, cmd_in, off_in, ccog_in, crip_in, dl_in, tn_in, g_in) = inner
    d_outer = derived_constants(p_out, dt_s, substeps)
    d_inner = derived_constants(p_in, dt_s, substeps)
    j_inner = carrier_inertia(p_in)
    inner_two_mass = p_in[P_J_LOAD] > 0.0
    outer_two_mass = p_out[P_J_LOAD] > 0.0
    n = cmd_out.shape[0]
    for k in range(n):
        first = control_period(p_out, s_out, cog_out, rip_out, cmd_out, off_out, ccog_out,
                               crip_out, dl_out, tn_out, g_out, outer_mode, outer_noise,
                               outer_out, k, dt_s, d_outer)
        second = control_period(p_in, s_in, cog_in, rip_in, cmd_in, off_in, ccog_in, crip_in,
                                dl_in, tn_in, g_in, inner_mode, inner_noise, inner_out, k,
                                dt_s, d_inner)
        if first == TRIPPED or second == TRIPPED:
            return k + 1
        for _ in range(substeps):
            el = s_in[S_THETA_L] if inner_two_mass else s_in[S_THETA_M]
            el_rate = s_in[S_OMEGA_L] if inner_two_mass else s_in[S_OMEGA_M]
            az_rate = s_out[S_OMEGA_L] if outer_two_mass else s_out[S_OMEGA_M]
            cos_el = math.cos(el)
            sin_el = math.sin(el)
            sin_2el = 2.0 * sin_el * cos_el
            cos_2el = cos_el * cos_el - sin_el * sin_el
            j_outer = (coupling[C_J_BASE] + coupling[C_DJ] * cos_el * cos_el
                       + coupling[C_P] * sin_2el)
            dj_outer = -coupling[C_DJ] * sin_2el + 2.0 * coupling[C_P] * cos_2el  # dJ/dθ
            c = coupling[C_CC] * cos_el + coupling[C_CS] * sin_el
            dc = -coupling[C_CC] * sin_el + coupling[C_CS] * cos_el
            on_outer = c * s_in[S_ACCEL] + dj_outer * el_rate * az_rate + dc * el_rate * el_rate
            on_inner = c * s_out[S_ACCEL] - 0.5 * dj_outer * az_rate * az_rate
            s_out[S_EXTERNAL] = on_outer  # a clamped rotor's sensor holds it too
            s_in[S_EXTERNAL] = on_inner
            if first == RUN_MECHANICS:
                mechanics_substep(p_out, s_out, cog_out, rip_out, d_outer, j_outer, on_outer)
            if second == RUN_MECHANICS:
                mechanics_substep(p_in, s_in, cog_in, rip_in, d_inner, j_inner, on_inner)
    return int(n)
