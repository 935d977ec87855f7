"""Azimuth inertia across elevation: the cos² fit on synthetic values, the gain scaling, the
simulator's elevation-dependent inertia, and recovery of a hidden payload (effects on)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.drives.sim import SimDrive
from hil.errors import IdentificationError
from hil.identify.estimate import Estimate
from hil.identify.inertia_elevation import fit_inertia_elevation, scale_by_gain
from hil.identify.torque_constant import identify_torque_constant
from hil.profile import load_profile
from hil.suite import inertia_elevation as protocol
from hil.suite import inertia_friction as sine
from hil.suite import torque_constant as kt
from plant_sim.params import PlantParams
from tests.helpers import drive_info

PROFILE = load_profile("demo_gimbal_azimuth")
FS = 4000.0
INFO = drive_info(PROFILE, FS)
SPEC = protocol.Spec.from_profile(PROFILE, INFO)
KT_SPEC = kt.Spec.from_profile(PROFILE, INFO)


def _accuracy(name: str) -> float:
    accuracy = PROFILE.measurement(name).accuracy_rel
    assert accuracy is not None
    return accuracy


def _j(value: float, u: float = 1e-5) -> Estimate:
    return Estimate(name="inertia_kg_m2", value=value, standard_uncertainty=u, unit="kg·m²")


def test_exact_cos2_law_is_recovered() -> None:
    elevations = [-1.2, -0.6, 0.0, 0.6, 1.2]
    result = fit_inertia_elevation(
        elevations, [_j(0.0065 + 0.0015 * math.cos(e) ** 2) for e in elevations])
    assert result.level.value == pytest.approx(0.008, rel=1e-12)
    assert result.zenith.value == pytest.approx(0.0065, rel=1e-12)


def test_uncertainty_follows_the_inputs() -> None:
    rng = np.random.default_rng(0)
    elevations = [-1.2, -0.6, 0.0, 0.6, 1.2]
    levels, us = [], []
    for _ in range(200):
        values = [0.0065 + 0.0015 * math.cos(e) ** 2 + rng.normal(0, 5e-5) for e in elevations]
        result = fit_inertia_elevation(elevations, [_j(v, 5e-5) for v in values])
        levels.append(result.level.value)
        us.append(result.level.standard_uncertainty)
    assert 0.7 < float(np.median(us)) / float(np.std(levels, ddof=1)) < 1.5


def test_a_shared_input_counts_once_and_cancels_in_the_ratio() -> None:
    """A gain error common to every J (one torque-constant result scales them all) moves
    level and zenith by the same fraction and the ratio not at all: over 400 draws of the
    common gain and the independent noise, the stated u of each result matches the
    scatter of its errors, which a fit treating the gain line as independent per
    elevation gets wrong both ways (too small for level, too large for the ratio)."""
    rng = np.random.default_rng(3)
    elevations = [-1.2, -0.6, 0.0, 0.6, 1.2]
    truth = [0.0065 + 0.0015 * math.cos(e) ** 2 for e in elevations]
    errors: dict[str, list[float]] = {"level": [], "zenith": [], "ratio": []}
    stated: dict[str, list[float]] = {"level": [], "zenith": [], "ratio": []}
    for _ in range(400):
        gain = 1.0 + rng.normal(0, 0.01)
        inertias = [scale_by_gain(_j(t + rng.normal(0, 2e-5), 2e-5), gain=gain, gain_u=0.01)
                    for t in truth]
        result = fit_inertia_elevation(elevations, inertias)
        for name, estimate, true in (("level", result.level, 0.008),
                                     ("zenith", result.zenith, 0.0065),
                                     ("ratio", result.ratio, 0.008 / 0.0065)):
            errors[name].append(estimate.value - true)
            stated[name].append(estimate.standard_uncertainty)
    for name in errors:
        ratio = float(np.std(errors[name])) / float(np.median(stated[name]))
        assert 0.85 < ratio < 1.15, (name, ratio)


def test_elevations_without_spread_are_refused() -> None:
    with pytest.raises(IdentificationError, match="span"):
        fit_inertia_elevation([0.0, 0.05, 0.1], [_j(0.008)] * 3)


def test_gain_scaling_combines_uncertainties() -> None:
    scaled = scale_by_gain(_j(0.008, 8e-5), gain=1.03, gain_u=0.0103)
    assert scaled.value == pytest.approx(0.00824)
    assert scaled.relative_uncertainty == pytest.approx(math.hypot(0.01, 0.01))


def test_simulated_inertia_follows_the_elevation() -> None:
    plant = PlantParams(inertia_kg_m2=0.004, inertia_elevation_kg_m2=-0.001)
    assert plant.total_inertia_kg_m2 == pytest.approx(0.003)
    assert plant.with_changes(elevation_rad=math.pi / 2).total_inertia_kg_m2 == pytest.approx(
        0.004)
    two_mass = PlantParams(inertia_kg_m2=0.003, load_inertia_kg_m2=0.0035,
                           shaft_stiffness_nm_rad=500.0, inertia_elevation_kg_m2=0.0015)
    assert two_mass.load_at_elevation_kg_m2 == pytest.approx(0.005)
    with pytest.raises(Exception, match="positive inertia"):
        PlantParams(inertia_kg_m2=0.001, inertia_elevation_kg_m2=-0.002)


@settings(max_examples=8, deadline=None)
@given(zenith_load=st.floats(0.002, 0.006), delta=st.floats(-0.0015, 0.003),
       kt_error=st.floats(-0.05, 0.05), seed=st.integers(0, 2**16))
def test_hidden_payload_inertia_is_recovered_within_the_claimed_accuracy(
    zenith_load: float, delta: float, kt_error: float, seed: int
) -> None:
    """The azimuth demo (two-mass, every effect on) with a hidden payload and K_t error;
    the K_t sweeps run first, as in the profile, and supply the torque gain."""
    assert PROFILE.plant is not None
    plant = PROFILE.plant.with_changes(load_inertia_kg_m2=zenith_load,
                                       inertia_elevation_kg_m2=delta,
                                       torque_constant_error_rel=kt_error)
    drive = SimDrive(plant, firmware=PROFILE.firmware, limits=PROFILE.limits, fs_hz=FS, seed=seed)
    with drive:
        drive.enable()
        sweeps = []
        for angle in KT_SPEC.angles_rad:
            drive.run(kt.move(KT_SPEC, position_rad=drive.status().position_rad,
                              angle_rad=angle))
            with drive.locked_rotor():
                recording = drive.run(kt.sweep(KT_SPEC, angle_rad=angle))
            sweeps.append(kt.analyse_sweep(recording, KT_SPEC, angle_rad=angle))
        gain = identify_torque_constant(sweeps).gain_error
        inertias = []
        for elevation in SPEC.elevations_rad:
            drive.set_elevation(elevation)
            recordings = [drive.run(e) for e in sine.excitation(SPEC.sine)]
            inertias.append(scale_by_gain(sine.analyse(recordings, SPEC.sine).inertia,
                                          gain=1 + gain.value / 100,
                                          gain_u=gain.standard_uncertainty / 100))
    result = fit_inertia_elevation(SPEC.elevations_rad, inertias)
    j_motor = plant.inertia_kg_m2
    assert result.level.value == pytest.approx(
        j_motor + zenith_load + delta, rel=_accuracy("azimuth_inertia_level_kg_m2"))
    assert result.zenith.value == pytest.approx(
        j_motor + zenith_load, rel=_accuracy("azimuth_inertia_zenith_kg_m2"))


def test_max_min_ratio_and_its_uncertainty() -> None:
    """J level / J zenith from the fit; its scatter over noisy inputs matches the reported u."""
    elevations = (-1.2, -0.6, 0.0, 0.6, 1.2)
    zenith, delta, u = 0.0065, 0.0015, 2e-5
    rng = np.random.default_rng(3)
    ratios, reported = [], []
    for _ in range(300):
        inertias = [Estimate(name="j", value=zenith + delta * math.cos(el) ** 2
                             + rng.normal(0, u), standard_uncertainty=u, unit="kg·m²")
                    for el in elevations]
        result = fit_inertia_elevation(elevations, inertias)
        ratios.append(result.ratio.value)
        reported.append(result.ratio.standard_uncertainty)
    assert np.mean(ratios) == pytest.approx((zenith + delta) / zenith, rel=1e-3)
    assert np.std(ratios) == pytest.approx(np.mean(reported), rel=0.15)


def test_the_sines_run_at_the_stated_stretch_or_where_the_axis_is() -> None:
    assert SPEC.sine.centre_rad == PROFILE.protocol("inertia_elevation")["centre_rad"]
    table = {k: v for k, v in PROFILE.protocols["inertia_elevation"].items()
             if k != "centre_rad"}
    inherited = dataclasses.replace(PROFILE, protocols={**PROFILE.protocols,
                                                        "inertia_elevation": table})
    assert protocol.Spec.from_profile(inherited, INFO).sine.centre_rad is None
