"""The compiled inner loop: drive loops at the control rate, mechanics at ``substeps`` per period.

Everything here is plain float arrays so numba compiles it once (cached on disk). The
Python side (:mod:`plant_sim.model`) packs parameters, draws noise and owns the state.
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
    N_PARAMS,
) = range(33)

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
    N_STATE,
) = range(12)

# rows of the in-loop noise array (one column per control period, drawn by the caller)
(
    L_SHAFT_NM,  # broadband torque disturbance on the shaft, held over the period
    L_SHAFT_LF_DRIVE_NM,  # white input of the low-frequency disturbance's filter
    L_CURRENT_SENSOR_NM,  # current-sensor noise in torque units (K_t·A): the loop follows it
    L_ENCODER_RAD,  # encoder jitter before quantisation
    N_LOOP_NOISE,
) = range(5)

MODE_TORQUE, MODE_VELOCITY, MODE_POSITION = 0, 1, 2

# the motion monitor's bounds (``guard``): measured position (rad), |velocity| (rad/s)
G_POSITION_MIN, G_POSITION_MAX, G_VELOCITY_MAX, G_SIZE = 0, 1, 2, 3


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
    """Advance ``len(command)`` control periods. Outputs are sampled at each period start.

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
            # friction with sticking: at rest until |t_drive| exceeds the breakaway torque
            if omega_m == 0.0:
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
    return int(done)
