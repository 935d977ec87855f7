"""An effect outside the library: not named as a known one, reported as unexplained.

Three shapes no known effect has (``unknown_effects.py``) are added to a simulated
recording: a tight spot in the bearing (Coulomb friction raised over 30 mrad of travel),
a backlash dead zone after each reversal, a stiffening (cubic) spring. The diagnoser must
name no cause (no known effect soaks them up with a significant gain: the halves test
compares each effect's coefficients between the two halves and between the middle and the
ends of the travel), say ``unexplained: true``, and say where the structure lies: the
tight spot's friction-like residual near its position, the backlash's within a few mrad of
each reversal, the spring's against position. Draws are derandomized (see
``test_diagnose_hidden.py``), two per shape; the benchmark measures more
(``bench_diagnose.py --unknown``, docs/diagnose.md).
"""

from __future__ import annotations

import pytest
from diagnose_simdata import plant_with, record
from hypothesis import given, settings
from hypothesis import strategies as st
from test_diagnose_hidden import DETERMINISTIC
from unknown_effects import bump_centre, hide_unknown

from hil.diagnose.core import diagnose
from hil.diagnose.report import report

#: The test that must find each shape's structure in the final held-out residual.
WHERE = {"friction_bump": "position_friction", "backlash": "reversal",
         "cubic_spring": "position"}
#: The tight spot is ``exp(−½((θ − θ₀)/w)²)``, ``w`` = 30 mrad: its residual's largest
#: position bin (of 40 over a ±0.6 rad travel, 30 mrad wide) lies within 2 w of θ₀.
BUMP_WIDTH_RAD = 0.03


@pytest.mark.parametrize("kind", sorted(WHERE))
@settings(DETERMINISTIC, max_examples=2)
@given(
    size=st.floats(0.0, 1.0),
    detail=st.floats(0.0, 1.0),
    inertia=st.floats(0.002, 0.006),
    coulomb=st.floats(0.015, 0.03),
    seed=st.integers(0, 2**16),
)
def test_unknown_effect_is_unexplained_not_misnamed(kind: str, size: float, detail: float,
                                                    inertia: float, coulomb: float,
                                                    seed: int) -> None:
    clean = plant_with(inertia, 0.005, coulomb, (), 60)
    plain = record(clean.params, seed=seed)
    recording = hide_unknown(plain, kind, size=size, detail=detail)
    data = report(diagnose(recording))
    assert [cause["name"] for cause in data["causes"]] == []
    assert data["unexplained"] is True
    structure = data["unexplained_structure"]
    assert structure["where"]
    test = structure["tests"][WHERE[kind]]
    assert test["found"], (kind, structure["where"])
    if kind == "friction_bump":
        centre = bump_centre(plain.position, detail)
        assert abs(test["peak"] - centre) < 2 * BUMP_WIDTH_RAD, (test["peak"], centre)
        assert test["peak_mean_nm"] > 0  # more friction there: opposing the motion
    if kind == "backlash":
        assert test["peak"] < 0.01  # within 10 mrad of a reversal (the gap is 2–6 mrad)
        assert test["peak_mean_nm"] < 0  # the load's friction missing there
