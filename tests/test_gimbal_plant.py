"""The two-axis gimbal plant: the single-axis plant as its special case, and the coupled
mechanics checked by what Lagrange's equations conserve (not by the kernel's own terms)."""

from __future__ import annotations

import numpy as np
import pytest

from hil.errors import ProfileError
from hil.motion import Mode
from hil.profile import load_profile
from plant_sim.gimbal import AxisBlock, GimbalPlant, coupling_vector, outer_inertia_kg_m2
from plant_sim.model import Plant
from plant_sim.params import PlantParams

FS = 4000.0


def _demo(axis: str) -> tuple[PlantParams, object]:
    profile = load_profile(f"demo_gimbal_{axis}")
    assert profile.plant is not None
    return profile.plant.with_changes(exact_torque_hold=True), profile.firmware


def test_a_gimbal_without_coupling_gives_each_axis_its_own_plants_recording() -> None:
    outer, outer_fw = _demo("azimuth")
    inner, inner_fw = _demo("elevation")
    outer = outer.with_changes(inertia_elevation_kg_m2=0.0, inertia_product_kg_m2=0.0,
                               inertia_coupling_level_kg_m2=0.0,
                               inertia_coupling_vertical_kg_m2=0.0)
    t = np.arange(12000) / FS
    commands = (0.8 * np.sin(2 * np.pi * 2.0 * t), 0.2 * np.sin(2 * np.pi * 0.7 * t))
    alone = [Plant(params, fs_hz=FS, seed=seed, firmware=fw).run(Mode.VELOCITY, command)
             for params, fw, seed, command in ((outer, outer_fw, 3, commands[0]),
                                               (inner, inner_fw, 4, commands[1]))]
    gimbal = GimbalPlant(Plant(outer, fs_hz=FS, seed=3, firmware=outer_fw),
                         Plant(inner, fs_hz=FS, seed=4, firmware=inner_fw))
    together = gimbal.run(AxisBlock(mode=Mode.VELOCITY, command=commands[0]),
                          AxisBlock(mode=Mode.VELOCITY, command=commands[1]))
    for one, both in zip(alone, together, strict=True):
        np.testing.assert_allclose(both.position_rad, one.position_rad, rtol=0, atol=1e-12)
        np.testing.assert_allclose(both.torque_nm, one.torque_nm, rtol=0, atol=1e-12)


def _free_gimbal(level: float, vertical: float) -> GimbalPlant:
    """Two frictionless rigid axes, ideal sensors, no noise: torque-free after a push."""
    outer = PlantParams(inertia_kg_m2=0.006, inertia_elevation_kg_m2=0.0015,
                        inertia_product_kg_m2=0.0004, inertia_coupling_level_kg_m2=level,
                        inertia_coupling_vertical_kg_m2=vertical, exact_torque_hold=True)
    inner = PlantParams(inertia_kg_m2=0.0036, exact_torque_hold=True)
    return GimbalPlant(Plant(outer, fs_hz=FS, seed=0), Plant(inner, fs_hz=FS, seed=0))


@pytest.mark.parametrize(("level", "vertical"), [(0.0, 0.0), (4e-4, -3e-4), (-6e-4, 5e-4)])
def test_angular_momentum_about_the_azimuth_and_energy_are_conserved(
        level: float, vertical: float) -> None:
    gimbal = _free_gimbal(level, vertical)
    push = np.zeros(400)
    push[:200] = 0.05  # both axes pushed, then left alone (torque mode, zero torque)
    gimbal.run(AxisBlock(mode=Mode.TORQUE, command=push),
               AxisBlock(mode=Mode.TORQUE, command=-1.5 * push))
    coupling = coupling_vector(gimbal.outer.params)
    momentum, energy = [], []
    for _ in range(400):  # 2 s of free motion, the elevation turning more than a radian
        gimbal.run(AxisBlock(mode=Mode.TORQUE, command=np.zeros(20)),
                   AxisBlock(mode=Mode.TORQUE, command=np.zeros(20)))
        el = np.array(gimbal.inner.position_rad)
        az_rate, el_rate = gimbal.outer.velocity_rad_s, gimbal.inner.velocity_rad_s
        j = float(outer_inertia_kg_m2(coupling, el))
        c = float(coupling[3] * np.cos(el) + coupling[4] * np.sin(el))
        momentum.append(j * az_rate + c * el_rate)
        energy.append(0.5 * (j * az_rate**2 + 2 * c * az_rate * el_rate + 0.0036 * el_rate**2))
    assert abs(gimbal.inner.position_rad) > 1.0  # J(θ) and c(θ) went through their range
    assert np.ptp(momentum) < 1e-4 * np.max(np.abs(momentum))
    assert np.ptp(energy) < 1e-4 * np.max(energy)


def test_the_azimuth_feels_the_elevation_accelerate_only_through_the_products() -> None:
    """An azimuth free to turn (torque mode, no friction) turns when the elevation swings
    only if the inner gimbal has products of inertia with its elevation axis."""
    moved = []
    for level in (0.0, 5e-4):
        gimbal = _free_gimbal(level, 0.0)
        swing = 0.05 * np.sign(np.sin(2 * np.pi * 2.0 * np.arange(4000) / FS))
        gimbal.run(AxisBlock(mode=Mode.TORQUE, command=np.zeros(4000)),
                   AxisBlock(mode=Mode.TORQUE, command=swing))
        moved.append(abs(gimbal.outer.velocity_rad_s) + abs(gimbal.outer.position_rad))
    assert moved[0] == 0.0
    assert moved[1] > 1e-3


def test_products_of_inertia_beyond_a_mass_matrix_are_refused() -> None:
    outer = PlantParams(inertia_kg_m2=0.006, inertia_coupling_level_kg_m2=0.004)
    inner = PlantParams(inertia_kg_m2=0.0036)
    with pytest.raises(ProfileError, match="inertia_coupling_level_kg_m2"):
        GimbalPlant(Plant(outer, fs_hz=FS, seed=0), Plant(inner, fs_hz=FS, seed=0))


def test_a_clamped_azimuths_sensor_holds_the_torque_of_the_swinging_elevation() -> None:
    """With the azimuth's rotor clamped through its shaft sensor, the elevation's swing
    reaches the clamp: the sensor reads −(c·θ̈ + c'·θ̇²) more than without products."""
    level, vertical = 4e-4, -3e-4
    t = np.arange(8000) / FS
    swing = 0.4 * 2 * np.pi * 1.5 * np.cos(2 * np.pi * 1.5 * t)  # ±0.4 rad at 1.5 Hz
    read = []
    for products in ((level, vertical), (0.0, 0.0)):
        gimbal = _free_gimbal(*products)
        gimbal.outer.set_locked_rotor(True)
        clamped, elevation = gimbal.run(AxisBlock(mode=Mode.TORQUE, command=np.zeros(t.size)),
                                        AxisBlock(mode=Mode.VELOCITY, command=swing))
        assert clamped.load_torque_nm is not None
        read.append(clamped.load_torque_nm)
    theta = elevation.position_rad
    rate = np.gradient(theta, 1 / FS)
    accel = np.gradient(rate, 1 / FS)
    c = level * np.cos(theta) + vertical * np.sin(theta)
    dc = -level * np.sin(theta) + vertical * np.cos(theta)
    expected = -(c * accel + dc * rate**2)
    got = read[0] - read[1]
    inside = slice(400, -400)  # the start's transient and the differences' edges
    assert np.corrcoef(got[inside], expected[inside])[0, 1] > 0.99
    assert np.std(got[inside]) == pytest.approx(np.std(expected[inside]), rel=0.05)
