"""J, B, T_c from sinusoidal velocity at two or more amplitudes (the article's experiment).

Library: :mod:`hil.suite.inertia_friction`.
"""

from __future__ import annotations

import pytest

from hil.calibration import CalibrationRun
from hil.drives.base import Drive
from hil.identify.inertia_friction import (
    InertiaFrictionResult,
    inertia_amplitude_spread,
)
from hil.profile import UnitProfile
from hil.suite.inertia_friction import (
    NAME,
    Spec,
    analyse_in_calibration,
    excitation,
    move_to_centre,
)

MEASUREMENTS = ("inertia_kg_m2", "viscous_nm_s_rad", "coulomb_nm", "inertia_amplitude_spread_pct")
pytestmark = pytest.mark.protocol(NAME)


@pytest.fixture(scope="module")
def result(
    drive: Drive, calibration: CalibrationRun, profile: UnitProfile
) -> InertiaFrictionResult:
    spec = Spec.from_profile(profile, drive.info)
    if spec.centre_rad is not None:
        move = move_to_centre(spec, spec.centre_rad, position_rad=drive.status().position_rad)
        calibration.run(drive, move, protocol=NAME)
    recordings = [calibration.run(drive, e, protocol=NAME) for e in excitation(spec)]
    analysed, corrections = analyse_in_calibration(recordings, spec, calibration)
    calibration.details[NAME] = {
        "method": spec.method,
        **corrections,
        "fit_pct": round(analysed.fit_pct, 2),
        "noise_rms_nm": analysed.noise_rms_nm,
        "components": [
            {
                "velocity_amplitude_rad_s": r.velocity_amplitude_rad_s,
                "quadrature_c_nm": r.quadrature_nm,
                "in_phase_s_nm": r.in_phase_nm,
                "periods": r.periods,
            }
            for r in analysed.runs
        ],
    }
    return analysed


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_inertia_friction(
    parameter: str, result: InertiaFrictionResult, calibration: CalibrationRun
) -> None:
    estimates = {e.name: e for e in (result.inertia, result.viscous, result.coulomb)}
    estimates["inertia_amplitude_spread_pct"] = inertia_amplitude_spread(result)
    measurement = calibration.record(NAME, estimates[parameter])
    assert measurement.conforms, measurement.verdict()
