"""The simulated axis: a stateful :class:`Plant` that runs command blocks through the kernel."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hil.motion import COMMAND_COLUMN, Mode
from hil.recording import Recording
from plant_sim import kernel
from plant_sim.firmware import Firmware
from plant_sim.params import Harmonic, PlantParams

FloatArray = NDArray[np.float64]


_KERNEL_MODE = {
    Mode.TORQUE: kernel.MODE_TORQUE,
    Mode.VELOCITY: kernel.MODE_VELOCITY,
    Mode.POSITION: kernel.MODE_POSITION,
}


@dataclass(frozen=True, slots=True, kw_only=True)
class PlantTrace:
    """What one block of control periods produced (the drive's view plus ground truth)."""

    time_s: FloatArray
    position_rad: FloatArray  # encoder, quantised
    velocity_rad_s: FloatArray  # drive's filtered estimate
    torque_nm: FloatArray  # commanded torque as reported, with measurement noise
    current_a: FloatArray  # actual q-axis current (after the current-loop lag)
    torque_actual_nm: FloatArray  # ground truth motor torque before K_t ripple
    load_torque_nm: FloatArray | None = None  # locked rotor: shaft torque sensor


@dataclass(frozen=True, slots=True, kw_only=True)
class MotionGuard:
    """A drive's motion monitor inside the kernel: the measured (encoder) position must stay
    in ``[position_min_rad, position_max_rad]`` and the velocity estimate within
    ``±velocity_max_rad_s``; the first period that leaves them is the last one run."""

    position_min_rad: float
    position_max_rad: float
    velocity_max_rad_s: float

    def packed(self) -> FloatArray:
        guard = np.zeros(kernel.G_SIZE)
        guard[kernel.G_POSITION_MIN] = self.position_min_rad
        guard[kernel.G_POSITION_MAX] = self.position_max_rad
        guard[kernel.G_VELOCITY_MAX] = self.velocity_max_rad_s
        return guard


PERIODIC_TABLE_SIZE = 1 << 16  # points per revolution for cogging and K_t ripple


def periodic_table(harmonics: tuple[Harmonic, ...]) -> FloatArray:
    """Sum of position harmonics over one revolution, closed (last point = first)."""
    if not harmonics:
        return np.zeros(0)
    theta = np.linspace(0.0, 2 * np.pi, PERIODIC_TABLE_SIZE + 1)
    table = np.zeros_like(theta)
    for harmonic in harmonics:
        table += harmonic.amplitude * np.sin(harmonic.order * theta + harmonic.phase_rad)
    table[-1] = table[0]
    return table


def pack_params(params: PlantParams, firmware: Firmware) -> FloatArray:
    """The kernel's parameter vector (the plant's physics and the drive's firmware)."""
    vector = np.zeros(kernel.N_PARAMS)
    vector[kernel.P_J_MOTOR] = params.motor_inertia_kg_m2
    vector[kernel.P_J_LOAD] = params.load_at_elevation_kg_m2
    vector[kernel.P_K_SHAFT] = params.shaft_stiffness_nm_rad
    vector[kernel.P_C_SHAFT] = params.shaft_damping_nm_s_rad
    vector[kernel.P_B_POS] = params.viscous_nm_s_rad
    vector[kernel.P_B_NEG] = (
        params.viscous_nm_s_rad
        if params.viscous_neg_nm_s_rad is None
        else params.viscous_neg_nm_s_rad
    )
    vector[kernel.P_TC_POS] = params.coulomb_nm
    vector[kernel.P_TC_NEG] = (
        params.coulomb_nm if params.coulomb_neg_nm is None else params.coulomb_neg_nm
    )
    vector[kernel.P_TS] = params.static_friction_nm
    vector[kernel.P_VS] = params.stribeck_velocity_rad_s
    vector[kernel.P_OFFSET] = params.torque_offset_nm
    vector[kernel.P_MGE] = params.gravity_mge_nm
    vector[kernel.P_GRAV_PHASE] = params.gravity_phase_rad
    vector[kernel.P_K_CABLE] = params.cable_stiffness_nm_rad
    vector[kernel.P_CABLE_ZERO] = params.cable_zero_rad
    vector[kernel.P_HYST_NM] = params.cable_hysteresis_nm
    vector[kernel.P_HYST_ANGLE] = params.cable_hysteresis_angle_rad
    vector[kernel.P_TAU_I] = firmware.current_loop_time_constant_s
    vector[kernel.P_T_MAX] = (
        params.torque_limit_nm if math.isfinite(params.torque_limit_nm) else 1e12
    )
    vector[kernel.P_COUNTS] = params.encoder_counts_per_rev
    vector[kernel.P_VEL_FILTER_HZ] = firmware.velocity_filter_hz
    vector[kernel.P_KP_VEL] = firmware.velocity_kp_nm_s_rad
    vector[kernel.P_KI_VEL] = firmware.velocity_ki_nm_rad
    vector[kernel.P_KP_POS] = params.position_kp_1_s
    vector[kernel.P_KT] = params.torque_constant_nm_a
    vector[kernel.P_EXACT_HOLD] = float(params.exact_torque_hold)
    vector[kernel.P_KT_SCALE] = 1.0 + params.torque_constant_error_rel
    vector[kernel.P_LOCKED] = float(params.locked_rotor)
    vector[kernel.P_DELAY] = firmware.command_delay_samples
    vector[kernel.P_FEEDFORWARD] = float(firmware.feedforward)
    vector[kernel.P_COMPENSATION] = float(firmware.cogging_compensation)
    sigma0 = params.bristle_stiffness_nm_rad
    vector[kernel.P_SIGMA0] = sigma0
    vector[kernel.P_SIGMA1] = 2 * params.bristle_damping_ratio * math.sqrt(
        sigma0 * params.motor_inertia_kg_m2)
    return vector


LOOP_NOISE_STREAM = 0x100B  # the in-loop noise's own stream of the seed (the reported
# torque's noise keeps the stream it always had, so a seed's measurement noise is unchanged)
ELEVATION_STEP_RAD = 1e-4  # the other axis moved less than this: the plant is not rebuilt


@dataclass(frozen=True, slots=True, kw_only=True)
class LoopNoiseScale:
    """Per-period standard deviations of the kernel's in-loop noise rows, and the
    low-frequency disturbance filter's decay per control period."""

    shaft_nm: float
    shaft_lf_drive_nm: float
    lf_decay: float
    current_sensor_nm: float
    encoder_rad: float

    @property
    def active(self) -> bool:
        return any(v > 0.0 for v in (self.shaft_nm, self.shaft_lf_drive_nm,
                                     self.current_sensor_nm, self.encoder_rad))


def loop_noise_scale(params: PlantParams, fs_hz: float) -> LoopNoiseScale:
    """The kernel's in-loop noise sizes for ``params`` at the control rate ``fs_hz``."""
    lf_decay = math.exp(-2.0 * math.pi * params.shaft_disturbance_lf_hz / fs_hz)
    # white drive of x[k] = a·x[k−1] + w[k] whose stationary RMS is the one asked for
    lf_drive = params.shaft_disturbance_lf_rms_nm * math.sqrt(1.0 - lf_decay**2)
    current_range_a = params.torque_limit_nm / params.torque_constant_nm_a
    sensor_nm = (params.current_sensor_noise_rms_rel * current_range_a
                 * params.torque_constant_nm_a if math.isfinite(current_range_a) else 0.0)
    counts = params.encoder_counts_per_rev
    encoder_rad = params.encoder_noise_rms_counts * 2 * math.pi / counts if counts > 0 else 0.0
    return LoopNoiseScale(shaft_nm=params.shaft_disturbance_rms_nm, shaft_lf_drive_nm=lf_drive,
                          lf_decay=lf_decay, current_sensor_nm=sensor_nm,
                          encoder_rad=encoder_rad)


def substeps_for(params: PlantParams, fs_hz: float) -> int:
    """Physics steps per control period: enough for the shaft resonance and the LuGre
    bristles' mode on the motor (ω·h ≤ 0.2)."""
    if params.substeps > 0:
        return params.substeps
    bristle_rad_s = math.sqrt(params.bristle_stiffness_nm_rad / params.motor_inertia_kg_m2)
    fastest_rad_s = max(2 * math.pi * params.resonance_hz, bristle_rad_s)
    if fastest_rad_s <= 0:
        return 1
    return max(1, math.ceil(fastest_rad_s / (0.2 * fs_hz)))


class Plant:
    """One simulated axis with its drive loops. Deterministic given ``seed``.

    ``run`` may be called repeatedly; state (position, integrators, filters) carries over,
    so an emulator can advance the plant one SYNC period at a time. ``firmware`` is the
    drive's controller (default: :class:`~plant_sim.firmware.Firmware`'s defaults).
    """

    def __init__(
        self,
        params: PlantParams,
        *,
        fs_hz: float,
        seed: int,
        firmware: Firmware | None = None,
        initial_position_rad: float = 0.0,
    ) -> None:
        if not fs_hz > 0:
            raise ValueError(f"fs_hz must be > 0, got {fs_hz}")
        self.params = params
        self.firmware = firmware or Firmware()
        self.fs_hz = float(fs_hz)
        self._packed = pack_params(params, self.firmware)
        self._delay_line = np.zeros(max(1, self.firmware.command_delay_samples))
        self._comp_cogging = np.zeros(0)
        self._comp_ripple = np.zeros(0)
        self._cogging = periodic_table(params.cogging)
        self._kt_ripple = periodic_table(params.kt_ripple)
        self._substeps = substeps_for(params, self.fs_hz)
        self._rng = np.random.default_rng(seed)
        self._loop_rng = np.random.default_rng((seed, LOOP_NOISE_STREAM))
        self._set_loop_noise()
        self._state = np.zeros(kernel.N_STATE)
        self._state[kernel.S_THETA_M] = initial_position_rad
        self._state[kernel.S_THETA_L] = initial_position_rad
        self._state[kernel.S_POS_MEAS_PREV] = kernel._quantise(
            initial_position_rad, float(params.encoder_counts_per_rev)
        )
        self._samples_done = 0

    @property
    def time_s(self) -> float:
        return self._samples_done / self.fs_hz

    @property
    def position_rad(self) -> float:
        """True motor-side position (not quantised)."""
        return float(self._state[kernel.S_THETA_M])

    @property
    def velocity_rad_s(self) -> float:
        return float(self._state[kernel.S_OMEGA_M])

    def set_locked_rotor(self, locked: bool) -> None:
        """Clamp (or release) the rotor through the shaft torque sensor; clamping stops it."""
        self.params = self.params.with_changes(locked_rotor=locked)
        self._packed[kernel.P_LOCKED] = float(locked)
        if locked:
            self._state[kernel.S_OMEGA_M] = 0.0
            self._state[kernel.S_OMEGA_L] = 0.0
            self._state[kernel.S_ACCEL] = 0.0

    def set_elevation(self, elevation_rad: float) -> None:
        """Move the other axis (elevation) of the station: the inertia about this axis
        follows ``inertia_elevation_kg_m2``."""
        self.params = self.params.with_changes(elevation_rad=elevation_rad)
        self._packed = pack_params(self.params, self.firmware)
        self._substeps = substeps_for(self.params, self.fs_hz)
        self._set_loop_noise()

    def follow_elevation(self, elevation_rad: float) -> None:
        """:meth:`set_elevation` when the other axis moved more than 0.1 mrad since it was
        last set (a holding axis's jitter does not rebuild the plant at every period)."""
        if abs(elevation_rad - self.params.elevation_rad) > ELEVATION_STEP_RAD:
            self.set_elevation(elevation_rad)

    def _set_loop_noise(self) -> None:
        self._loop_noise = loop_noise_scale(self.params, self.fs_hz)
        self._packed[kernel.P_LF_DECAY] = self._loop_noise.lf_decay

    def _draw_loop_noise(self, n: int) -> FloatArray:
        """The kernel's in-loop noise rows for ``n`` periods (no columns when all are off)."""
        scale = self._loop_noise
        if not scale.active:
            return np.zeros((kernel.N_LOOP_NOISE, 0))
        noise = np.zeros((kernel.N_LOOP_NOISE, n))
        for row, size in ((kernel.L_SHAFT_NM, scale.shaft_nm),
                          (kernel.L_SHAFT_LF_DRIVE_NM, scale.shaft_lf_drive_nm),
                          (kernel.L_CURRENT_SENSOR_NM, scale.current_sensor_nm),
                          (kernel.L_ENCODER_RAD, scale.encoder_rad)):
            if size > 0.0:  # only the rows that are on (drawing is a third of the run's time)
                self._loop_rng.standard_normal(n, out=noise[row])
                noise[row] *= size
        return noise

    def load_compensation(
        self, cogging: tuple[Harmonic, ...], kt_ripple: tuple[Harmonic, ...] = ()
    ) -> None:
        """Load a cogging compensation table into the drive (empty: none). The drive applies
        it only when its firmware has ``cogging_compensation``."""
        self._comp_cogging = periodic_table(cogging)
        self._comp_ripple = periodic_table(kt_ripple)

    def hold(self) -> None:
        """Reset the velocity integrator (what a drive does on disable/enable)."""
        self._state[kernel.S_INTEGRATOR] = 0.0

    def run(
        self,
        mode: Mode,
        command: FloatArray,
        torque_offset: FloatArray | None = None,
        *,
        guard: MotionGuard | None = None,
    ) -> PlantTrace:
        """Advance one control period per command sample; ``torque_offset`` (N·m, one per
        sample) is the master's torque offset, which the firmware adds when it has
        ``feedforward``. With ``guard`` the run stops after the first period whose measured
        position or velocity leaves it: the trace is then shorter than ``command``."""
        block = self.block(command, torque_offset, guard=guard)
        (params, cogging, kt_ripple, state, command, offset, comp_cogging, comp_ripple,
         delay_line, noise, guard_values) = block.arrays
        run_kernel: Callable[..., int] = kernel.run_kernel
        done = run_kernel(params, cogging, kt_ripple, state, _KERNEL_MODE[mode], command, offset,
                          comp_cogging, comp_ripple, delay_line, noise, block.loop_noise,
                          1.0 / self.fs_hz, self._substeps, *block.out,
                          guard_values)
        return self.advance(block, done)

    def block(self, command: FloatArray, torque_offset: FloatArray | None = None, *,
              guard: MotionGuard | None = None) -> KernelBlock:
        """The kernel's inputs and outputs for ``command`` (one sample per period): this
        axis's arrays (its state among them, advanced in place by the kernel), its noise."""
        command = np.ascontiguousarray(command, dtype=np.float64)
        n = command.shape[0]
        offset = (np.zeros(0) if torque_offset is None
                  else np.ascontiguousarray(torque_offset, dtype=np.float64))
        if offset.shape[0] not in (0, n):
            raise ValueError(f"torque_offset has {offset.shape[0]} samples, command {n}")
        noise = np.asarray(self._rng.normal(0.0, 1.0, n) * self.params.torque_noise_nm)
        arrays = (self._packed, self._cogging, self._kt_ripple, self._state, command, offset,
                  self._comp_cogging, self._comp_ripple, self._delay_line, noise,
                  np.zeros(0) if guard is None else guard.packed())
        return KernelBlock(arrays=arrays, loop_noise=self._draw_loop_noise(n),
                           out=np.empty((kernel.N_OUT, n)))

    def advance(self, block: KernelBlock, done: int) -> PlantTrace:
        """The trace of the ``done`` periods the kernel ran of ``block`` (the clock moved)."""
        out = block.out[:, :done]
        time_s = (self._samples_done + np.arange(done)) / self.fs_hz
        self._samples_done += done
        load_torque = None
        if self.params.locked_rotor:
            noise_sensor = self._rng.normal(0.0, 1.0, done) * self.params.load_torque_noise_nm
            load_torque = out[kernel.O_LOAD_TORQUE] + noise_sensor
        return PlantTrace(
            time_s=time_s,
            position_rad=out[kernel.O_POSITION],
            velocity_rad_s=out[kernel.O_VELOCITY],
            torque_nm=out[kernel.O_TORQUE],
            current_a=out[kernel.O_CURRENT],
            torque_actual_nm=out[kernel.O_TORQUE_ACTUAL],
            load_torque_nm=load_torque,
        )


def concatenate_traces(traces: list[PlantTrace]) -> PlantTrace:
    """Consecutive traces as one (empty when there are none); the shaft sensor's column
    only when every one has it."""
    def joined(name: str) -> FloatArray:
        return np.concatenate([getattr(t, name) for t in traces]) if traces else np.zeros(0)
    load = [t.load_torque_nm for t in traces if t.load_torque_nm is not None]
    return PlantTrace(time_s=joined("time_s"), position_rad=joined("position_rad"),
                      velocity_rad_s=joined("velocity_rad_s"), torque_nm=joined("torque_nm"),
                      current_a=joined("current_a"), torque_actual_nm=joined("torque_actual_nm"),
                      load_torque_nm=np.concatenate(load) if traces and len(load) == len(traces)
                      else None)


@dataclass(frozen=True, slots=True)
class KernelBlock:
    """One axis's arrays for a kernel call (``kernel.A_*`` order), its in-loop noise rows
    and the output rows the kernel fills (``kernel.O_*``)."""

    arrays: tuple[FloatArray, ...]
    loop_noise: FloatArray
    out: FloatArray


def trace_to_recording(
    trace: PlantTrace,
    *,
    mode: Mode,
    command: FloatArray,
    metadata: dict[str, str] | None = None,
) -> Recording:
    """The recording a drive would deliver for ``trace`` (ground truth left out)."""
    columns = {
        "time_s": trace.time_s,
        "position_rad": trace.position_rad,
        "velocity_rad_s": trace.velocity_rad_s,
        "torque_nm": trace.torque_nm,
        COMMAND_COLUMN[mode]: np.asarray(command, dtype=np.float64),
        "current_a": trace.current_a,
    }
    if trace.load_torque_nm is not None:
        columns["load_torque_nm"] = trace.load_torque_nm
    return Recording(columns=columns, metadata=dict(metadata or {}), source="plant_sim")


def simulate(
    params: PlantParams,
    *,
    mode: Mode,
    command: FloatArray,
    fs_hz: float,
    seed: int,
    firmware: Firmware | None = None,
    initial_position_rad: float = 0.0,
) -> Recording:
    """Simulate ``command`` (one sample per control period) from rest and return a Recording."""
    plant = Plant(params, fs_hz=fs_hz, seed=seed, firmware=firmware,
                  initial_position_rad=initial_position_rad)
    trace = plant.run(mode, command)
    metadata = {"drive": "plant_sim", "control_mode": mode.value, "seed": str(seed)}
    return trace_to_recording(trace, mode=mode, command=command, metadata=metadata)
