"""Physical and drive parameters of one simulated gimbal axis.

Every effect is off by default in :class:`PlantParams` (an ideal axis for the numerics'
tests), and so is the noise inside the loops unless a ``[plant]`` table names it:
:data:`LOOP_NOISE_DEFAULTS` gives the sizes a real unit has, each with its reason, and the
demo profiles name them. The closed-loop protocols' Type A is built for such noise: the
tracking move's repeated runs, standstill blocks held at several positions, the ripple
fit's fixed-b Newey–West bandwidth (``tests/closed_loop/test_loop_noise_budgets.py``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, fields, replace
from typing import Any, Final, get_type_hints

from hil.config import ConfigTable
from hil.errors import ProfileError
from plant_sim.firmware import refuse_moved_keys


@dataclass(frozen=True, slots=True, kw_only=True)
class Harmonic:
    """One position harmonic: ``amplitude * sin(order * theta + phase_rad)``."""

    order: int
    amplitude: float
    phase_rad: float = 0.0


LOOP_NOISE_DEFAULTS: Final[dict[str, float]] = {
    # 0.2 mN·m: bearing and seal running-torque ripple and the base's vibration, about 1 %
    # of a small gimbal axis' Coulomb friction (the demo's is 20 mN·m)
    "shaft_disturbance_rms_nm": 2e-4,
    # 0: optional (a drifting load such as wind or a cable that relaxes); off unless a
    # profile names it, as it moves the mechanics results of a run as a whole
    "shaft_disturbance_lf_rms_nm": 0.0,
    # 0.2 % of the current range: a 12-bit converter spanning ± the range adds 0.014 % RMS;
    # shunt-amplifier noise and PWM pick-up put a servo drive's current noise at 0.1–0.3 %
    # (the demo: 10 mA of 5 A, 1 mN·m at K_t 0.1 N·m/A, under its torque noise of 1.5 mN·m)
    "current_sensor_noise_rms_rel": 0.002,
    # 0.3 counts: a high-resolution absolute or interpolated encoder's jitter is a fraction
    # of a count (datasheets: about ±1 count peak); the demo's 19 bits make it 3.6 µrad
    "encoder_noise_rms_counts": 0.3,
}
"""The in-loop noise sizes of a real unit, for a ``[plant]`` table to name (the demo
profiles do; an unnamed key is 0)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class PlantParams:
    """A gimbal axis (its drive's controller settings are :class:`plant_sim.firmware.Firmware`).

    Mechanics: ``J·α = T_motor·(1 + K_t ripple(θ)) − cogging(θ) − friction(ω) − gravity(θ)
    − cable(θ) − offset``; with ``load_inertia_kg_m2 > 0`` a two-mass system whose load is
    coupled by a spring-damper shaft (gravity, cable and offset act on the load).
    Friction: ``[T_c + (T_s − T_c)·exp(−(ω/v_s)²)]·sgn(ω) + B·ω`` with true sticking at
    ω = 0 until the applied torque exceeds ``T_s``.
    """

    inertia_kg_m2: float
    viscous_nm_s_rad: float = 0.0
    coulomb_nm: float = 0.0
    static_friction_nm: float = 0.0  # T_s; below coulomb_nm means no Stribeck peak
    stribeck_velocity_rad_s: float = 0.02
    coulomb_neg_nm: float | None = None  # asymmetric friction: negative direction
    viscous_neg_nm_s_rad: float | None = None
    torque_offset_nm: float = 0.0  # constant load torque the motor must hold
    # LuGre friction instead of the static map with sticking: the bristles' deflection at the
    # breakaway torque (σ0 = max(T_s, T_c)/presliding_rad); 0: the static map
    presliding_rad: float = 0.0
    bristle_damping_ratio: float = 0.7  # LuGre: σ1 = 2ζ·√(σ0·J_motor)
    load_inertia_kg_m2: float = 0.0  # > 0: two-mass model
    shaft_stiffness_nm_rad: float = 0.0
    shaft_damping_nm_s_rad: float = 0.0
    cogging: tuple[Harmonic, ...] = ()  # amplitude in N·m
    kt_ripple: tuple[Harmonic, ...] = ()  # amplitude relative to K_t
    gravity_mge_nm: float = 0.0  # holding torque m·g·e·cos(θ + gravity_phase_rad)
    gravity_phase_rad: float = 0.0
    cable_stiffness_nm_rad: float = 0.0
    cable_zero_rad: float = 0.0
    cable_hysteresis_nm: float = 0.0  # half width of the Dahl hysteresis loop
    cable_hysteresis_angle_rad: float = 0.02  # travel over which hysteresis saturates
    torque_constant_nm_a: float = 0.1
    torque_limit_nm: float = math.inf
    encoder_counts_per_rev: int = 0  # 0: ideal encoder
    torque_noise_nm: float = 0.0  # std of white noise on the reported torque
    position_kp_1_s: float = 30.0
    substeps: int = 0  # physics steps per control period; 0: chosen from the dynamics
    # True: the held (zero-order hold) motor torque moves the position by its exact double
    # integral over each physics step; False: the symplectic step's full weight (a half-step
    # time advance of the motion against the torque, kept as the default for old results)
    exact_torque_hold: bool = False
    # true K_t = torque_constant_nm_a·(1 + error): the drive converts current with the nominal,
    # so the reported torque is off by this factor against the shaft's torque
    torque_constant_error_rel: float = 0.0
    locked_rotor: bool = False  # rotor clamped through a shaft torque sensor (load_torque_nm)
    load_torque_noise_nm: float = 0.0  # std of white noise on the torque sensor
    # azimuth axis carrying the elevation stage: the payload's inertia about this axis is
    # J + inertia_elevation_kg_m2·cos²(el) + inertia_product_kg_m2·sin(2·el) at
    # el = elevation_rad (on the load of a two-mass axis); the product is the stage's
    # product of inertia between its level and zenith axes
    inertia_elevation_kg_m2: float = 0.0
    inertia_product_kg_m2: float = 0.0
    # and the stage's products of inertia of its elevation axis with the zenith and the
    # line of sight: c(el) = level·cos(el) + vertical·sin(el) couples the two axes'
    # accelerations (plant_sim.gimbal; no effect while the elevation stands still)
    inertia_coupling_level_kg_m2: float = 0.0
    inertia_coupling_vertical_kg_m2: float = 0.0
    elevation_rad: float = 0.0  # the other axis' angle (station state)
    # --- noise inside the loops (what makes two runs of one unit differ), drawn from the
    # run's seed; sizes a real unit has are LOOP_NOISE_DEFAULTS ---
    # broadband torque disturbance on the shaft, white and held over each control period
    shaft_disturbance_rms_nm: float = 0.0
    # low-frequency shaft disturbance: first-order low-passed white noise of this RMS
    shaft_disturbance_lf_rms_nm: float = 0.0
    shaft_disturbance_lf_hz: float = 0.5  # its corner frequency
    # current-sensor noise RMS as a fraction of the drive's current range
    # (torque_limit_nm / torque_constant_nm_a; none with an unlimited torque): the current
    # loop follows it, so the torque made differs from the demand by it
    current_sensor_noise_rms_rel: float = 0.0
    # encoder jitter ahead of the quantiser, in counts (none with an ideal encoder)
    encoder_noise_rms_counts: float = 0.0

    def __post_init__(self) -> None:
        if not self.inertia_kg_m2 > 0:
            raise ProfileError(f"inertia_kg_m2 must be > 0, got {self.inertia_kg_m2}")
        for name in (
            "viscous_nm_s_rad",
            "coulomb_nm",
            "static_friction_nm",
            "load_inertia_kg_m2",
            "shaft_stiffness_nm_rad",
            "shaft_damping_nm_s_rad",
            "cable_stiffness_nm_rad",
            "cable_hysteresis_nm",
            "presliding_rad",
            "torque_noise_nm",
            "load_torque_noise_nm",
            *LOOP_NOISE_DEFAULTS,
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ProfileError(f"{name} must be finite and >= 0, got {value}")
        if not self.shaft_disturbance_lf_hz > 0:
            raise ProfileError("shaft_disturbance_lf_hz must be > 0")
        if self.stribeck_velocity_rad_s <= 0:
            raise ProfileError("stribeck_velocity_rad_s must be > 0")
        if self.cable_hysteresis_angle_rad <= 0:
            raise ProfileError("cable_hysteresis_angle_rad must be > 0")
        if self.load_inertia_kg_m2 > 0 and self.shaft_stiffness_nm_rad <= 0:
            raise ProfileError("a two-mass plant needs shaft_stiffness_nm_rad > 0")
        # the smallest over elevation: base + ΔJ/2 − √(ΔJ²/4 + P²)
        swing = math.hypot(self.inertia_elevation_kg_m2 / 2, self.inertia_product_kg_m2)
        if self.effective_inertias_kg_m2(elevation_rad=0.0)[0] - (
                self.inertia_elevation_kg_m2 / 2 + swing) <= 0:
            raise ProfileError("inertia_elevation_kg_m2 and inertia_product_kg_m2 leave no "
                               "positive inertia at some elevation")
        if not self.torque_constant_error_rel > -1.0:
            raise ProfileError("torque_constant_error_rel must be > -1")
        if not self.torque_limit_nm > 0:
            raise ProfileError("torque_limit_nm must be > 0")

    def effective_inertias_kg_m2(self, *, elevation_rad: float) -> tuple[float, float]:
        """(motor, load) inertia with the elevation-dependent part at ``elevation_rad`` (the
        part that depends on elevation sits on the load of a two-mass axis, else on the
        motor; the first element is that part's carrier for the positivity check)."""
        extra = (self.inertia_elevation_kg_m2 * math.cos(elevation_rad) ** 2
                 + self.inertia_product_kg_m2 * math.sin(2.0 * elevation_rad))
        if self.load_inertia_kg_m2 > 0:
            return self.load_inertia_kg_m2 + extra, self.inertia_kg_m2
        return self.inertia_kg_m2 + extra, 0.0

    @property
    def motor_inertia_kg_m2(self) -> float:
        """Motor-side inertia at ``elevation_rad``."""
        if self.load_inertia_kg_m2 > 0:
            return self.inertia_kg_m2
        return self.effective_inertias_kg_m2(elevation_rad=self.elevation_rad)[0]

    @property
    def load_at_elevation_kg_m2(self) -> float:
        """Load inertia at ``elevation_rad`` (0 for a rigid axis)."""
        if self.load_inertia_kg_m2 <= 0:
            return 0.0
        return self.effective_inertias_kg_m2(elevation_rad=self.elevation_rad)[0]

    @property
    def total_inertia_kg_m2(self) -> float:
        return self.motor_inertia_kg_m2 + self.load_at_elevation_kg_m2

    @property
    def resonance_hz(self) -> float:
        """Two-mass resonance (0 for a rigid axis)."""
        load = self.load_at_elevation_kg_m2
        if load <= 0:
            return 0.0
        reduced = self.motor_inertia_kg_m2 * load / self.total_inertia_kg_m2
        return math.sqrt(self.shaft_stiffness_nm_rad / reduced) / (2 * math.pi)

    @property
    def bristle_stiffness_nm_rad(self) -> float:
        """LuGre's σ0 (0 for the static map)."""
        if self.presliding_rad <= 0:
            return 0.0
        return max(self.static_friction_nm, self.coulomb_nm) / self.presliding_rad

    def with_changes(self, **changes: Any) -> PlantParams:
        return replace(self, **changes)


_HARMONIC_FIELDS = ("cogging", "kt_ripple")


def plant_from_mapping(data: Mapping[str, Any], *, source: str = "[plant]") -> PlantParams:
    """Build :class:`PlantParams` from a parsed ``[plant]`` table (see :func:`plant_from_table`)."""
    return plant_from_table(ConfigTable(data, table="[plant]", source=source))


def plant_from_table(table: ConfigTable) -> PlantParams:
    """Build :class:`PlantParams` from a ``[plant]`` table.

    Every key is a field of :class:`PlantParams`, of that field's type; harmonics are lists
    of ``{order, amplitude, phase_rad}``.

    Raises
    ------
    ProfileError
        An unknown key, a wrong type or a value out of range, naming file, table and key.
    """
    refuse_moved_keys(table)
    hints = get_type_hints(PlantParams)
    kwargs: dict[str, Any] = {}
    for f in fields(PlantParams):
        if f.name not in table and f.default is not MISSING:
            continue  # required fields fall through and are reported missing
        kind = hints[f.name]
        if f.name in _HARMONIC_FIELDS:
            kwargs[f.name] = tuple(_harmonic(item) for item in table.table_list(f.name))
        elif kind is bool:
            kwargs[f.name] = table.boolean(f.name)
        elif kind is int:
            kwargs[f.name] = table.integer(f.name)
        else:  # float or float | None
            kwargs[f.name] = table.number(f.name)
    table.done()
    try:
        return PlantParams(**kwargs)
    except ProfileError as exc:
        raise ProfileError(f"{table.table} {exc.message}", source=table.source) from None


def _harmonic(item: ConfigTable) -> Harmonic:
    harmonic = Harmonic(
        order=item.integer("order"),
        amplitude=item.number("amplitude"),
        phase_rad=item.number("phase_rad", 0.0),
    )
    item.done()
    return harmonic


def plant_to_mapping(params: PlantParams) -> dict[str, Any]:
    """Inverse of :func:`plant_from_table` (non-default values and the loop noise, TOML-ready)."""
    out: dict[str, Any] = {}
    for f in fields(PlantParams):
        value = getattr(params, f.name)
        if value is None:
            continue
        default = f.default
        if value == default and f.name not in LOOP_NOISE_DEFAULTS:
            continue  # the loop noise is always written, none as 0
        if f.name in _HARMONIC_FIELDS:
            out[f.name] = [
                {"order": h.order, "amplitude": h.amplitude, "phase_rad": h.phase_rad}
                for h in value
            ]
        elif isinstance(value, float) and math.isinf(value):
            continue
        else:
            out[f.name] = value
    return out
