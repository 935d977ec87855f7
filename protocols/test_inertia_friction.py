"""J, B, T_c from sinusoidal velocity at two or more amplitudes (the article's experiment).

With ``stop_at_u_fraction`` in its table the sines run again (at most ``max_runs`` times)
until every judged result's U is at most that fraction of its tolerance half-width; the
certificate's details say how many runs and why (:mod:`hil.suite.stop_rule`).

Library: :mod:`hil.suite.inertia_friction`.
"""

from __future__ import annotations

import pytest

from hil.calibration import CalibrationRun
from hil.drives.base import Drive, DriveInfo
from hil.identify.estimate import Estimate
from hil.identify.inertia_friction import InertiaFrictionResult
from hil.measurement import WITHOUT_POSITION_TORQUE, Declared, declare
from hil.motion import Mode
from hil.profile import UnitProfile
from hil.suite.inertia_friction import (
    MEASUREMENTS,
    NAME,
    NEEDS,
    EarlierInputs,
    InertiaFrictionDetails,
    SineComponent,
    Spec,
    analyse_in_calibration,
    motion,
)
from hil.suite.needs import note_fallbacks
from hil.suite.position_torque import measured_position_torque
from hil.suite.shaft_input import shaft_input
from hil.suite.stop_rule import run_repeated

pytestmark = pytest.mark.protocol(NAME)

# what the certificate calls each result, and one line on what it is
DECLARED = declare(
    Declared("inertia_kg_m2", "Moment of inertia",
             "Rotor and load inertia about the axis, from the sinusoidal-velocity runs",
             non_negative=True),
    Declared("viscous_nm_s_rad", "Viscous friction",
             "B: friction torque per unit speed, from the same sines' torque in phase with the "
             "speed"),
    Declared("coulomb_nm", "Coulomb friction",
             "T_c: the friction torque that does not depend on speed, from the same sines"),
    Declared("inertia_amplitude_spread_pct", "Inertia agreement between amplitudes",
             "Largest minus smallest J of the sine runs at different amplitudes, in % of J: J must"
             " not depend on the amplitude", non_negative=True),
)


@pytest.fixture(scope="module")
def result(
    drive: Drive, calibration: CalibrationRun, profile: UnitProfile,
           drive_info: DriveInfo
) -> dict[str, Estimate]:
    spec = Spec.from_profile(profile, drive_info)
    note_fallbacks(calibration, NAME, NEEDS)
    # the protocol's one sequence (the planner sums the same): the centre move, the sines
    sequence = list(motion(spec, position=lambda: drive.status().position_rad))
    sines = [e for e in sequence if e.mode is not Mode.POSITION]
    for move in sequence[:len(sequence) - len(sines)]:  # once: a repeat stays at the centre
        calibration.run(drive, move, protocol=NAME)

    # cogging and K_t ripple from the gravity sweep: the ripple modulates J·α over the travel
    position_torque = measured_position_torque(calibration, profile, drive.info, protocol=NAME)
    # a two-mass axis's load driven through the shaft the resonance protocol measured
    shaft = shaft_input(calibration)

    def run_once() -> tuple[InertiaFrictionResult, dict[str, Estimate], EarlierInputs]:
        recordings = [calibration.run(drive, e, protocol=NAME) for e in sines]
        return analyse_in_calibration(recordings, spec, calibration,
                                      position_torque=position_torque, shaft=shaft)

    runs = run_repeated(run_once, lambda found: found[1], rule=spec.stop, calibration=calibration,
                        variant=lambda found: None if found[2].position_torque_removed != "none"
                        else WITHOUT_POSITION_TORQUE)
    analysed, _, corrections = runs.first  # the first run's fit and inputs, for the details
    calibration.details[NAME] = InertiaFrictionDetails(
        **runs.details(),
        method=spec.method,
        frequency_hz=spec.frequency_hz,
        settle_periods=spec.settle_periods,
        centre_rad=corrections.centre_rad,
        load_stiffness_nm_rad=corrections.load_stiffness_nm_rad,
        cable_loop_removed=corrections.cable_loop_removed,
        current_loop_lag_compensated_s=corrections.current_loop_lag_compensated_s,
        position_torque_removed=corrections.position_torque_removed,
        shaft_modes=corrections.shaft_modes,
        fit_pct=round(analysed.fit_pct, 2),
        noise_rms_nm=analysed.noise_rms_nm,
        components=tuple(
            SineComponent(velocity_amplitude_rad_s=r.velocity_amplitude_rad_s,
                          quadrature_c_nm=r.quadrature_nm, in_phase_s_nm=r.in_phase_nm,
                          periods=r.periods)
            for r in analysed.runs
        ),
    )
    return runs.estimates


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_inertia_friction(
    parameter: str, result: dict[str, Estimate], calibration: CalibrationRun
) -> None:
    details = calibration.details[NAME]
    taken_out = (isinstance(details, InertiaFrictionDetails)
                 and details.position_torque_removed != "none")
    measurement = calibration.record(NAME, result[parameter], declared=DECLARED[parameter],
                                     variant=None if taken_out else WITHOUT_POSITION_TORQUE)
    assert measurement.conforms, measurement.verdict()
