"""A second simulator whose own choices are drawn: test data that no single simulator shapes.

The main simulator (:mod:`plant_sim.model`) makes one set of choices a recording carries
the marks of: its integrator, its friction law, its loop, its noise. A diagnosis or a
method map tuned on it can lean on them. :class:`Variant` names those choices, and
:func:`simulate_variant` runs a unit's physics (:class:`~plant_sim.params.PlantParams`,
:class:`~plant_sim.firmware.Firmware`) through another implementation
(:mod:`plant_sim.variant_kernel`) with them: the integrator and its sub-steps, a static
Stribeck map or LuGre friction with drawn bristles at the same ``T_c``/``T_s``/``v_s``, the
velocity estimator, the PI's structure and a torque-command filter, the sample rate and
jittered periods, when the new torque acts within a period, the encoder's resolution,
white or coloured torque noise, and the torque reported before or after the current loop.
:func:`draw_variant` draws them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Final, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

from hil.recording import Recording
from plant_sim import variant_kernel as vk
from plant_sim.firmware import Firmware
from plant_sim.params import Harmonic, PlantParams

FloatArray = NDArray[np.float64]

Integrator = Literal["symplectic_euler", "heun", "rk4"]
FrictionLaw = Literal["static", "lugre"]
Estimator = Literal["filtered_difference", "moving_average", "tracking_observer"]
NoiseColour = Literal["white", "low_pass"]
TorqueTap = Literal["command", "measured"]

_SUPPORTED: Final = frozenset({
    "inertia_kg_m2", "viscous_nm_s_rad", "coulomb_nm", "static_friction_nm",
    "stribeck_velocity_rad_s", "coulomb_neg_nm", "viscous_neg_nm_s_rad", "torque_offset_nm",
    "load_inertia_kg_m2", "shaft_stiffness_nm_rad", "shaft_damping_nm_s_rad", "cogging",
    "kt_ripple", "gravity_mge_nm", "gravity_phase_rad", "cable_stiffness_nm_rad",
    "cable_zero_rad", "torque_constant_nm_a", "torque_limit_nm", "encoder_counts_per_rev",
    "torque_noise_nm", "position_kp_1_s", "substeps", "exact_torque_hold",
    "cable_hysteresis_angle_rad", "shaft_disturbance_lf_hz",
})
"""The :class:`PlantParams` fields this simulator takes (any other must keep its default):
the unit's physics, plus the main simulator's own integrator settings (``substeps``,
``exact_torque_hold``), the position loop's gain (velocity mode only here) and two
parameters of effects left out (the cable loop's angle, the drifting load's corner), which
it ignores."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Variant:
    """A simulator's own choices, apart from the unit's physics."""

    integrator: Integrator = "symplectic_euler"
    substeps: int = 8  # raised where a bristle or shaft mode needs it
    friction_law: FrictionLaw = "static"
    presliding_rad: float = 5e-5  # LuGre: the bristles' deflection at the static torque
    bristle_damping_ratio: float = 0.7  # LuGre: σ1 = 2ζ·√(σ0·J)
    stick_band_rad_s: float = 1e-4  # static law: Karnopp's zero-velocity band
    estimator: Estimator = "filtered_difference"
    estimator_hz: float = 300.0  # filter corner or observer bandwidth
    moving_average_taps: int = 4
    setpoint_weight: float = 1.0  # PI: T = Kp·(b·ω* − ω̂) + Ki·∫(ω* − ω̂); 1 the parallel form
    torque_filter_hz: float = 0.0  # first-order low-pass of the torque command (0: none)
    sample_rate_hz: float = 2000.0
    period_jitter_rel: float = 0.0  # std of each control period over its nominal
    apply_delay_rel: float = 0.0  # part of a period before a new torque command acts
    encoder_counts_per_rev: int = 2**20  # 0: ideal
    noise_colour: NoiseColour = "white"
    noise_corner_hz: float = 200.0  # low_pass noise: first-order corner
    torque_tap: TorqueTap = "command"
    shaft_noise_nm: float = 0.0  # white torque disturbance on the shaft, held per period

    def __post_init__(self) -> None:
        if self.integrator not in vk.INTEGRATOR_NAMES:
            raise ValueError(f"integrator must be one of {vk.INTEGRATOR_NAMES}")
        if self.substeps < 1 or self.moving_average_taps < 1:
            raise ValueError("substeps and moving_average_taps must be >= 1")
        if not (self.sample_rate_hz > 0 and self.presliding_rad > 0 and self.estimator_hz > 0):
            raise ValueError("sample_rate_hz, presliding_rad and estimator_hz must be > 0")
        if self.estimator == "tracking_observer" and self.estimator_hz > self.sample_rate_hz / 10:
            raise ValueError("a tracking observer's bandwidth must be <= sample_rate_hz / 10")
        if not 0 <= self.setpoint_weight <= 1:
            raise ValueError("setpoint_weight must be in [0, 1]")
        if not 0 <= self.apply_delay_rel < 1 or not 0 <= self.period_jitter_rel < 0.1:
            raise ValueError("apply_delay_rel must be in [0, 1), period_jitter_rel in [0, 0.1)")

    def labels(self) -> dict[str, str]:
        """Each choice as a short label, for rates per variant."""
        return {
            "integrator": f"{self.integrator}",
            "friction": self.friction_law,
            "estimator": self.estimator,
            "loop": ("parallel PI" if self.setpoint_weight == 1 else "2-DOF PI")
                    + (" + torque filter" if self.torque_filter_hz else ""),
            "rate": f"{self.sample_rate_hz:g} Hz" + (" jittered" if self.period_jitter_rel
                                                     else ""),
            "encoder": (f"2^{round(math.log2(self.encoder_counts_per_rev))}"
                        if self.encoder_counts_per_rev else "ideal"),
            "noise": self.noise_colour,
            "torque": self.torque_tap,
        }


MAIN_LIKE: Final = Variant()
"""The choices closest to the main simulator's (its integrator, law, estimator and loop)."""


class UnstableLoopError(ValueError):
    """The variant's loop does not hold the unit (a choice no drive would ship)."""


def draw_variant(rng: np.random.Generator) -> Variant:
    """A variant with every choice drawn (each option equally likely)."""

    def pick(options: tuple[str, ...]) -> str:
        return options[int(rng.integers(len(options)))]

    integrator = pick(vk.INTEGRATOR_NAMES)
    rate_hz = float(rng.choice((1000.0, 2000.0, 4000.0)))
    estimator = pick(("filtered_difference", "moving_average", "tracking_observer"))
    estimator_hz = float(rng.uniform(150.0, 400.0))
    if estimator == "tracking_observer":
        estimator_hz = min(estimator_hz, rate_hz / 10)
    return Variant(
        integrator=integrator,  # type: ignore[arg-type]
        substeps=int(rng.choice((1, 2, 4, 8))),
        friction_law=pick(("static", "lugre")),  # type: ignore[arg-type]
        presliding_rad=float(10 ** rng.uniform(-5.0, -3.7)),
        bristle_damping_ratio=float(rng.uniform(0.3, 1.0)),
        stick_band_rad_s=float(10 ** rng.uniform(-5.0, -3.0)),
        estimator=estimator,  # type: ignore[arg-type]
        estimator_hz=estimator_hz,
        moving_average_taps=int(rng.integers(2, 7)),
        setpoint_weight=float(rng.choice((1.0, rng.uniform(0.5, 0.9)))),
        torque_filter_hz=float(rng.choice((0.0, rng.uniform(400.0, 1500.0)))),
        sample_rate_hz=rate_hz,
        period_jitter_rel=float(rng.choice((0.0, rng.uniform(0.002, 0.02)))),
        apply_delay_rel=float(rng.uniform(0.0, 0.6)),
        encoder_counts_per_rev=int(2 ** int(rng.integers(17, 23))),
        noise_colour=pick(("white", "low_pass")),  # type: ignore[arg-type]
        noise_corner_hz=float(rng.uniform(20.0, 300.0)),
        torque_tap=pick(("command", "measured")),  # type: ignore[arg-type]
        shaft_noise_nm=float(rng.uniform(0.0, 3e-4)),
    )


def _harmonic_rows(harmonics: tuple[Harmonic, ...]) -> FloatArray:
    rows = [(h.order, h.amplitude, h.phase_rad) for h in harmonics]
    return np.array(rows, dtype=np.float64).reshape(len(rows), 3)


def _refuse_unsupported(plant: PlantParams, firmware: Firmware) -> None:
    for field in fields(plant):
        if field.name not in _SUPPORTED and getattr(plant, field.name) != field.default:
            raise ValueError(f"plant_sim.variant does not model {field.name}")
    if firmware.command_delay_samples or firmware.feedforward or firmware.cogging_compensation:
        raise ValueError("plant_sim.variant models neither command delays, feedforward nor "
                         "compensation tables")


#: sub-steps the current loop's time constant spans at least, per integrator: an
#: integrator's phase error is a lag (or lead) the unit does not have, and the first-order
#: symplectic Euler's position leads by half a step (1.6 % of τ at 32)
CURRENT_LOOP_STEPS: Final = {"symplectic_euler": 32, "heun": 16, "rk4": 4}


def _substeps(plant: PlantParams, firmware: Firmware, variant: Variant, sigma0: float) -> int:
    """The variant's sub-steps, raised until the stiffest mode has ≥ 12 steps per radian,
    the current loop's τ is resolved (:data:`CURRENT_LOOP_STEPS`) and a late command can
    act within the period (to a quarter of it)."""
    motor = plant.inertia_kg_m2
    stiffest = sigma0 / motor if variant.friction_law == "lugre" else 0.0
    if plant.load_inertia_kg_m2 > 0:
        reduced = motor * plant.load_inertia_kg_m2 / (motor + plant.load_inertia_kg_m2)
        stiffest = max(stiffest, plant.shaft_stiffness_nm_rad / reduced)
    needed = math.ceil(12.0 * math.sqrt(stiffest) / variant.sample_rate_hz)
    tau_s = firmware.current_loop_time_constant_s
    current = (math.ceil(CURRENT_LOOP_STEPS[variant.integrator]
                         / (tau_s * variant.sample_rate_hz)) if tau_s > 0 else 1)
    timing = 4 if variant.apply_delay_rel else 1  # the command acts a quarter-period late
    return max(variant.substeps, needed, current, timing)


def apply_delay_s(plant: PlantParams, firmware: Firmware, variant: Variant) -> float:
    """When a new torque command acts within its period, as simulated: the drawn part of
    the period rounded to the sub-steps the run takes (s)."""
    substeps = _run_substeps(plant, firmware, variant)
    return round(variant.apply_delay_rel * substeps) / substeps / variant.sample_rate_hz


def _run_substeps(plant: PlantParams, firmware: Firmware, variant: Variant) -> int:
    """The sub-steps a run of ``plant`` takes (:func:`_substeps` at its bristles' σ0)."""
    static = max(plant.static_friction_nm, plant.coulomb_nm)
    return _substeps(plant, firmware, variant,
                     static / variant.presliding_rad if static > 0 else 0.0)


def torque_lag_s(plant: PlantParams, firmware: Firmware, variant: Variant) -> float:
    """The lag the simulated motion has behind the reported command below the current
    loop's bandwidth (s): the loop's τ, plus the part of a period before a command acts,
    less symplectic Euler's lead (its position steps with the step's new velocity, half a
    sub-step ahead of the motion it integrates: a lead the unit does not have but the
    recording does, −1.05 % of τ over 100 of this module's units)."""
    lag = firmware.current_loop_time_constant_s + apply_delay_s(plant, firmware, variant)
    if variant.integrator != "symplectic_euler":
        return lag
    return lag - 0.5 / (_run_substeps(plant, firmware, variant) * variant.sample_rate_hz)


def _parameters(plant: PlantParams, firmware: Firmware, variant: Variant) -> FloatArray:
    p = np.zeros(vk.N_V)
    static = max(plant.static_friction_nm, plant.coulomb_nm)
    sigma0 = static / variant.presliding_rad if static > 0 else 0.0
    lugre = variant.friction_law == "lugre" and sigma0 > 0
    counts = variant.encoder_counts_per_rev
    p[vk.V_J_MOTOR] = plant.inertia_kg_m2
    p[vk.V_J_LOAD] = plant.load_inertia_kg_m2
    p[vk.V_K_SHAFT] = plant.shaft_stiffness_nm_rad
    p[vk.V_C_SHAFT] = plant.shaft_damping_nm_s_rad
    p[vk.V_B_POS] = plant.viscous_nm_s_rad
    p[vk.V_B_NEG] = (plant.viscous_nm_s_rad if plant.viscous_neg_nm_s_rad is None
                     else plant.viscous_neg_nm_s_rad)
    p[vk.V_TC_POS] = plant.coulomb_nm
    p[vk.V_TC_NEG] = plant.coulomb_nm if plant.coulomb_neg_nm is None else plant.coulomb_neg_nm
    p[vk.V_TS] = plant.static_friction_nm
    p[vk.V_VS] = plant.stribeck_velocity_rad_s
    p[vk.V_OFFSET] = plant.torque_offset_nm
    p[vk.V_MGE] = plant.gravity_mge_nm
    p[vk.V_GRAV_PHASE] = plant.gravity_phase_rad
    p[vk.V_K_CABLE] = plant.cable_stiffness_nm_rad
    p[vk.V_CABLE_ZERO] = plant.cable_zero_rad
    p[vk.V_TAU_I] = firmware.current_loop_time_constant_s
    p[vk.V_KP] = firmware.velocity_kp_nm_s_rad
    p[vk.V_KI] = firmware.velocity_ki_nm_rad
    p[vk.V_KT] = plant.torque_constant_nm_a
    p[vk.V_STEP_RAD] = 2 * math.pi / counts if counts else 0.0
    p[vk.V_INTEGRATOR] = vk.INTEGRATOR_NAMES.index(variant.integrator)
    p[vk.V_SUBSTEPS] = _substeps(plant, firmware, variant, sigma0)
    p[vk.V_LUGRE] = float(lugre)
    p[vk.V_SIGMA0] = sigma0
    p[vk.V_SIGMA1] = 2 * variant.bristle_damping_ratio * math.sqrt(sigma0 * plant.inertia_kg_m2)
    p[vk.V_STICK_BAND] = variant.stick_band_rad_s
    p[vk.V_ESTIMATOR] = ("filtered_difference", "moving_average",
                         "tracking_observer").index(variant.estimator)
    p[vk.V_ESTIMATOR_HZ] = variant.estimator_hz
    p[vk.V_MA_TAPS] = variant.moving_average_taps
    p[vk.V_SETPOINT_WEIGHT] = variant.setpoint_weight
    p[vk.V_TORQUE_FILTER_HZ] = variant.torque_filter_hz
    p[vk.V_APPLY_DELAY] = variant.apply_delay_rel
    p[vk.V_TAP_MEASURED] = float(variant.torque_tap == "measured")
    p[vk.V_NOMINAL_DT] = 1.0 / variant.sample_rate_hz
    return p


def _torque_noise(rng: np.random.Generator, n: int, rms_nm: float, variant: Variant) -> FloatArray:
    white = rng.normal(0.0, rms_nm, n)
    if variant.noise_colour == "white" or rms_nm == 0:
        return white
    decay = math.exp(-2 * math.pi * variant.noise_corner_hz / variant.sample_rate_hz)
    # first-order low-pass scaled to the same RMS, from the first sample's value
    coloured, _ = lfilter([math.sqrt(1 - decay**2)], [1.0, -decay], white,
                          zi=[decay * white[0]])
    return np.asarray(coloured, dtype=np.float64)


def simulate_variant(plant: PlantParams, firmware: Firmware, variant: Variant, *,
                     velocity_command_rad_s: FloatArray, seed: int) -> Recording:
    """A velocity-mode run of ``plant`` under ``firmware``, simulated with ``variant``'s
    choices (``velocity_command_rad_s`` one value per control period at its sample rate)."""
    _refuse_unsupported(plant, firmware)
    command = np.ascontiguousarray(velocity_command_rad_s, dtype=np.float64)
    n = command.shape[0]
    rng = np.random.default_rng(seed)
    dt = 1.0 / variant.sample_rate_hz
    jitter = np.clip(rng.normal(0.0, variant.period_jitter_rel, n), -0.05, 0.05)
    periods = dt * (1.0 + jitter)
    noise = _torque_noise(rng, n, plant.torque_noise_nm, variant)
    disturbance = np.asarray(rng.normal(0.0, variant.shaft_noise_nm, n), dtype=np.float64)
    t_max = plant.torque_limit_nm if math.isfinite(plant.torque_limit_nm) else 1e9
    out = [np.empty(n) for _ in range(4)]
    vk.run_variant(_parameters(plant, firmware, variant), _harmonic_rows(plant.cogging),
                   _harmonic_rows(plant.kt_ripple), command, periods, noise,
                   disturbance, t_max, *out)
    position, velocity, torque, current = out
    target = np.cumsum(command) / variant.sample_rate_hz
    miss = np.max(np.abs(position - target)) if np.all(np.isfinite(position)) else math.inf
    if miss > 0.5:
        raise UnstableLoopError(f"the loop lost the unit: {miss:.3g} rad off the commanded path")
    time_s = np.concatenate(([0.0], np.cumsum(periods[:-1])))
    labels = "; ".join(f"{k} {v}" for k, v in variant.labels().items())
    return Recording(
        columns={"time_s": time_s, "position_rad": position, "velocity_rad_s": velocity,
                 "torque_nm": torque, "velocity_cmd_rad_s": command, "current_a": current},
        metadata={"drive": "plant_sim.variant", "control_mode": "velocity", "seed": str(seed),
                  "variant": labels,
                  "torque_reports": ("measured_current" if variant.torque_tap == "measured"
                                     else "demand")},
        source="plant_sim.variant")
