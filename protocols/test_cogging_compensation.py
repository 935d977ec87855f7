"""Cogging compensation effectiveness: the residual cogging (position ripple at the table's
orders) of one constant-velocity pass with the drive's table cleared and loaded.

Uses the ``cogging_compensation.json`` the cogging protocol wrote in this calibration.

Library: :mod:`hil.suite.cogging_compensation`.
"""

from __future__ import annotations

import json
from collections.abc import Iterator

import pytest

from hil.calibration import CalibrationRun
from hil.drives.base import Drive, DriveInfo
from hil.identify.estimate import Estimate
from hil.measurement import Declared, declare
from hil.motion import Mode
from hil.profile import UnitProfile
from hil.suite.cogging import CoggingDetails
from hil.suite.cogging_compensation import (
    MEASUREMENTS,
    NAME,
    NEEDS,
    REMOVED,
    REQUIRES,
    TABLE,
    TABLE_LINE,
    CoggingCompensationDetails,
    LargestOrder,
    Spec,
    analyse,
    excitation,
    motion,
    orders,
    table_from_json,
    table_relative_uncertainty,
    unresolved,
)
from hil.suite.needs import note_fallbacks
from hil.suite.rate import sample_rate_shortfall
from hil.suite.stop_rule import run_repeated

pytestmark = pytest.mark.protocol(NAME)

# what the certificate calls each result, and one line on what it is
DECLARED = declare(
    Declared("cogging_ripple_uncompensated_urad", "Cogging ripple, table off",
             "Largest position ripple at the cogging orders in a constant-velocity pass, the "
             "drive's compensation table cleared", non_negative=True),
    Declared("cogging_ripple_compensated_urad", "Cogging ripple, table on",
             "The same with this calibration's compensation table loaded into the drive",
             non_negative=True),
    Declared("cogging_compensation_removed_pct", "Cogging removed by the table",
             "Share of the position ripple the compensation table removes, in %"),
)


@pytest.fixture(scope="module")
def cleared(drive: Drive) -> Iterator[Drive]:
    """The drive, its compensation table cleared again afterwards whatever happened."""
    if (lacking := drive.info.lacking(REQUIRES)) is not None:
        pytest.skip(lacking)
    drive.load_compensation(None)
    try:
        yield drive
    finally:
        drive.load_compensation(None)


@pytest.fixture(scope="module")
def result(cleared: Drive, calibration: CalibrationRun, profile: UnitProfile,
           drive_info: DriveInfo
           ) -> dict[str, Estimate]:
    drive = cleared
    note_fallbacks(calibration, NAME, NEEDS)
    cogging = calibration.details.get(TABLE.protocol)
    if not isinstance(cogging, CoggingDetails):
        pytest.skip("no cogging_compensation.json in this calibration (the cogging protocol "
                    "did not run before this one)")
    path = cogging.compensation_table  # in the unit's folder
    with (calibration.unit_dir / path).open(encoding="utf-8") as handle:
        data = json.load(handle)
    table = table_from_json(data)
    spec = Spec.from_profile(profile, drive_info)
    shortfall = sample_rate_shortfall(
        spec.needed_sample_rate_hz, drive_info, protocol=NAME,
        why=f"≥ {spec.min_samples_per_pass} samples in the {spec.pass_s - spec.skip_s:g} s "
            "analysed pass")
    if shortfall is not None:
        pytest.skip(shortfall)
    off, on = excitation(spec)
    relative_u = table_relative_uncertainty(data)

    def run_once() -> tuple[dict[str, Estimate], list[int]]:
        recorded = []
        # the protocol's one sequence (the planner sums the same): per run a move, the run
        for e in motion(spec, (off, on), position=lambda: drive.status().position_rad):
            if e.mode is Mode.POSITION:
                calibration.run(drive, e, protocol=NAME)
                continue
            drive.load_compensation(None if e is off else table)
            recorded.append(calibration.run(drive, e, protocol=NAME))
        drive.load_compensation(None)
        recorded_off, recorded_on = recorded
        return analyse((recorded_off, off), (recorded_on, on), spec, table,
                       table_relative_u=relative_u)

    runs = run_repeated(run_once, lambda found: found[0], rule=spec.stop,
                        calibration=calibration, shared=(TABLE_LINE,))
    largest = runs.first[1]
    calibration.details[NAME] = CoggingCompensationDetails(
        **runs.details(),
        table=path,
        orders=tuple(orders(table)),
        table_relative_uncertainty={str(n): u for n, u in relative_u.items()},
        largest_order=LargestOrder(cleared=largest[0], loaded=largest[1]),
        # for the plot: the analysed stretch of each pass, from its first sample
        analysed_s=(spec.ramp_s + spec.skip_s, spec.ramp_s + spec.pass_s),
    )
    return runs.estimates


@pytest.mark.parametrize("parameter", MEASUREMENTS)
def test_cogging_compensation(parameter: str, result: dict[str, Estimate],
                              calibration: CalibrationRun) -> None:
    if parameter == REMOVED and (why := unresolved(result)) is not None:
        calibration.state_unresolved(NAME, parameter, why)  # the residual is judged
        return
    measurement = calibration.record(NAME, result[parameter],
                                     declared=DECLARED[parameter])
    assert measurement.conforms, measurement.verdict()
