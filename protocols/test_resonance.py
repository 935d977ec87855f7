"""Two-mass resonance f_r, anti-resonance f_a, damping and f_r / velocity-loop bandwidth from
the FRF of a periodic multisine (or, if the profile asks, a stepped sine; numerics in
:mod:`hil.identify.resonance`).

Velocity-mode lines over the profile's band, on a constant-speed carrier (no reversal, so
friction stays linear). Skips on a unit whose profile has no ``[protocols.resonance]``
(a rigid axis: nothing to find).

Library: :mod:`hil.suite.resonance`.
"""

from __future__ import annotations

import math

import pytest

from hil.calibration import CalibrationRun
from hil.drives.base import Drive, DriveInfo
from hil.identify.estimate import Estimate
from hil.identify.resonance import ResonanceResult
from hil.measurement import Declared, declare
from hil.motion import Mode
from hil.profile import UnitProfile
from hil.suite.needs import note_fallbacks
from hil.suite.rate import sample_rate_shortfall
from hil.suite.resonance import (
    MEASUREMENTS,
    NAME,
    NEEDS,
    FrfPoint,
    MultisineSpec,
    ResonanceDetails,
    analyse,
    excitation,
    measured_time_constant_s,
    spec_from_profile,
)

pytestmark = pytest.mark.protocol(NAME)

# what the certificate calls each result, and one line on what it is
DECLARED = declare(
    Declared("resonance_frequency_hz", "Resonance frequency",
             "f_r: the load's two-mass resonance, from the frequency response to a multisine "
             "(two-mass fit)"),
    Declared("antiresonance_frequency_hz", "Anti-resonance frequency",
             "f_a: the dip below the resonance, where the load absorbs the motor's motion"),
    Declared("resonance_damping_ratio", "Resonance damping ratio",
             "ζ of the two-mass mode fitted to the frequency response", non_negative=True),
    Declared("resonance_to_bandwidth_ratio", "Resonance over loop bandwidth",
             "f_r over the velocity loop's bandwidth: 5 or more keeps the mode clear of the loop",
             non_negative=True),
)


@pytest.fixture(scope="module")
def result(drive: Drive, calibration: CalibrationRun, profile: UnitProfile,
           drive_info: DriveInfo) -> ResonanceResult:
    if NAME not in profile.protocols:
        pytest.skip(
            f"the profile has no [protocols.{NAME}] table: a rigid axis, no shaft "
            "resonance to identify"
        )
    spec = spec_from_profile(profile, drive_info)
    shortfall = sample_rate_shortfall(
        spec.needed_sample_rate_hz,
        drive_info,
        protocol=NAME,
        why=f"4 × the top of its band, {max(spec.frequencies_hz):g} Hz",
    )
    if shortfall is not None:
        pytest.skip(shortfall)
    note_fallbacks(calibration, NAME, NEEDS)
    recordings = [recording for e in excitation(spec, position_rad=drive.status().position_rad)
                  if (recording := calibration.run(drive, e, protocol=NAME)) is not None
                  and e.mode is not Mode.POSITION]  # the moves are not analysed
    analysed = analyse(recordings, spec, time_constant_s=measured_time_constant_s(calibration))
    m = analysed.model
    calibration.details[NAME] = ResonanceDetails(
        excitation="multisine" if isinstance(spec, MultisineSpec) else "stepped_sine",
        model="P/T = (s²/ωa² + 2ζa s/ωa + 1)/(s²/ωr² + 2ζr s/ωr + 1) / (J s (s + B/J)(τ s + 1))",
        inertia_total_kg_m2=m.inertia_kg_m2,
        antiresonance_damping_ratio=m.antiresonance_damping,
        viscous_over_inertia_1_s=m.viscous_over_inertia_1_s,
        current_loop_time_constant_s=m.time_constant_s,
        velocity_loop_bandwidth_hz=analysed.bandwidth_hz,
        chi2_per_dof=analysed.chi2_per_dof,
        frf=tuple(
            FrfPoint(frequency_hz=p.frequency_hz, magnitude_rad_nm=abs(p.frf_rad_nm),
                     phase_rad=math.atan2(p.frf_rad_nm.imag, p.frf_rad_nm.real),
                     relative_u=p.relative_u, coherence=p.coherence)
            for p in analysed.points
        ),
    )
    return analysed


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_resonance(parameter: str, result: ResonanceResult, calibration: CalibrationRun) -> None:
    found: dict[str, Estimate] = {
        e.name: e for e in (result.resonance, result.antiresonance, result.damping, result.ratio)
    }
    # the ratio is f_r over a bandwidth read off the same FRF: f_r's method terms are its own
    method_of = "resonance_frequency_hz" if parameter == "resonance_to_bandwidth_ratio" else None
    measurement = calibration.record(NAME, found[parameter], method_of=method_of,
                                     declared=DECLARED[parameter])
    assert measurement.conforms, measurement.verdict()
