"""Recordings from the project's simulator with (at most) one hidden effect."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hil.motion import Mode
from hil.recording import Recording
from plant_sim.firmware import Firmware
from plant_sim.model import simulate
from plant_sim.params import Harmonic, PlantParams
from plant_sim.variant import Variant, simulate_variant

FS_HZ = 2000.0
FloatArray = NDArray[np.float64]


def excitation(fs_hz: float = FS_HZ, *, scale: float = 1.0) -> FloatArray:
    """Gimbal test run: two 2 Hz sines, a slow staircase, a full sweep, a log chirp."""
    parts: list[FloatArray] = []
    t = np.arange(int(2.0 * fs_hz)) / fs_hz
    parts.extend(a * scale * np.sin(2 * np.pi * 2.0 * t) for a in (0.5, 1.0))
    parts.extend(np.full(int(0.75 * fs_hz), v) for v in (0.01, -0.01, 0.03, -0.03, 0.1, -0.1))
    n = int(6.0 * fs_hz)
    sweep = np.full(n, 0.4)
    sweep[n // 4 : 3 * n // 4] = -0.4
    parts.append(sweep)
    duration = 4.0
    t = np.arange(int(duration * fs_hz)) / fs_hz
    rate = math.log(150.0) / duration
    parts.append(0.2 * np.sin(2 * np.pi * (np.exp(rate * t) - 1) / rate))
    return np.concatenate(parts)


BASE: dict[str, Any] = {
    "encoder_counts_per_rev": 2**20,
    "torque_noise_nm": 0.002,
}
FIRMWARE = Firmware(velocity_filter_hz=300.0, velocity_kp_nm_s_rad=0.45, velocity_ki_nm_rad=12.0)


@dataclass(frozen=True, slots=True, kw_only=True)
class SimUnit:
    """A simulated axis and its drive's firmware."""

    plant: PlantParams
    firmware: Firmware


@dataclass(frozen=True, slots=True, kw_only=True)
class Hidden:
    """What was hidden (never shown to the diagnoser) and its key parameter's truth."""

    effect: str | None
    key: str | None
    truth: float
    params: SimUnit


@dataclass(frozen=True, slots=True, kw_only=True)
class Truth:
    """One hidden effect and its key parameter's true value."""

    effect: str
    key: str
    truth: float


@dataclass(frozen=True, slots=True, kw_only=True)
class HiddenSet:
    """Several hidden effects (never shown to the diagnoser) in one simulated unit."""

    truths: tuple[Truth, ...]
    params: SimUnit


def _add(base: dict[str, Any], firmware: Firmware, inertia: float, viscous: float,
         coulomb: float, effect: str, size: float, detail: float,
         order: int) -> tuple[Truth, Firmware]:
    """Hide ``effect`` in ``base`` (sized by ``size`` in [0, 1], shaped by ``detail``)."""
    if effect == "offset":
        truth = math.copysign(0.006 + 0.024 * size, detail - 0.5)
        base["torque_offset_nm"], key = truth, "offset_nm"
    elif effect == "asymmetric_friction":
        truth = viscous * (2.5 + 2.0 * size)
        base["viscous_neg_nm_s_rad"], key = truth, "viscous_neg"
    elif effect == "stribeck":
        truth = coulomb * (1.4 + 0.6 * size)
        base.update(static_friction_nm=truth, stribeck_velocity_rad_s=0.012 + 0.03 * detail)
        key = "static_torque_nm"
    elif effect == "cogging":
        truth = 0.002 + 0.006 * size
        base["cogging"] = (Harmonic(order=order, amplitude=truth, phase_rad=6 * detail),)
        key = "amplitude_nm"
    elif effect == "kt_ripple":
        truth = 0.1 + 0.1 * size
        base["kt_ripple"] = (Harmonic(order=order // 2, amplitude=truth, phase_rad=6 * detail),)
        key = "relative_amplitude"
    elif effect == "gravity":
        truth = 0.01 + 0.04 * size
        base.update(gravity_mge_nm=truth, gravity_phase_rad=detail - 0.5)
        key = "mge_nm"
    elif effect == "cable_spring":
        # below ~0.012 N·m/rad with its zero off-centre, a spring over this ±0.6 rad sweep is
        # explained as well by gravity (ΔBIC within 5 of each other at 0.010): not revealable
        truth = 0.013 + 0.027 * size
        base.update(cable_stiffness_nm_rad=truth, cable_zero_rad=0.4 * (detail - 0.5))
        key = "stiffness_nm_per_rad"
    elif effect == "current_lag":
        truth = 0.0015 + 0.0025 * size
        firmware, key = firmware.with_changes(current_loop_time_constant_s=truth), "time_constant_s"
    elif effect == "two_mass":
        ratio = 2.0 + 4.0 * detail
        truth = 30.0 + 50.0 * size
        motor = inertia / (1 + ratio)
        load = inertia - motor
        reduced = motor * load / inertia
        stiffness = (2 * math.pi * truth) ** 2 * reduced
        damping = 2 * 0.03 * math.sqrt(stiffness * reduced)
        base.update(inertia_kg_m2=motor, load_inertia_kg_m2=load,
                    shaft_stiffness_nm_rad=stiffness, shaft_damping_nm_s_rad=damping)
        key = "resonance_hz"
    else:
        raise ValueError(f"unknown effect {effect!r}")
    return Truth(effect=effect, key=key, truth=truth), firmware


def plant_with(inertia: float, viscous: float, coulomb: float,
               effects: tuple[tuple[str, float, float], ...], order: int) -> HiddenSet:
    """A plant with every ``(effect, size, detail)`` of ``effects`` hidden in it."""
    base = dict(BASE, inertia_kg_m2=inertia, viscous_nm_s_rad=viscous, coulomb_nm=coulomb)
    firmware = FIRMWARE
    truths = []
    for effect, size, detail in effects:
        truth, firmware = _add(base, firmware, inertia, viscous, coulomb, effect, size, detail,
                               order)
        truths.append(truth)
    return HiddenSet(truths=tuple(truths),
                     params=SimUnit(plant=PlantParams(**base), firmware=firmware))


def plant(inertia: float, viscous: float, coulomb: float, effect: str | None,
          size: float, detail: float, order: int) -> Hidden:
    """A plant with ``effect`` (sized by ``size`` in [0, 1], shaped by ``detail``)."""
    hidden = plant_with(inertia, viscous, coulomb,
                        ((effect, size, detail),) if effect else (), order)
    if not hidden.truths:
        return Hidden(effect=None, key=None, truth=math.nan, params=hidden.params)
    only = hidden.truths[0]
    return Hidden(effect=only.effect, key=only.key, truth=only.truth, params=hidden.params)


def record(params: SimUnit, *, seed: int, scale: float = 1.0,
           variant: Variant | None = None) -> Recording:
    """The test run of ``params``: by the project's simulator, or by ``plant_sim.variant``
    with ``variant``'s choices."""
    if variant is None:
        return simulate(params.plant, mode=Mode.VELOCITY, command=excitation(scale=scale),
                        fs_hz=FS_HZ, seed=seed, firmware=params.firmware)
    return simulate_variant(params.plant, params.firmware, variant, seed=seed,
                            velocity_command_rad_s=excitation(variant.sample_rate_hz,
                                                              scale=scale))


def observable(truths: tuple[Truth, ...], variant: Variant | None) -> tuple[Truth, ...]:
    """The hidden effects a recording can show: a current-loop lag acts before a torque
    reported after the current loop (the measured current), so it is not in its data."""
    if variant is None or variant.torque_tap == "command":
        return truths
    return tuple(t for t in truths if t.effect != "current_lag")
