"""The recordings of a simulator that is not this project's: name the right cause, each time.

They are a check, not a training set: nothing in ``hil.diagnose`` knows these files.
"""

from __future__ import annotations

import json
import math
from functools import cache
from pathlib import Path
from typing import Any

import pytest

from hil.diagnose.core import diagnose
from hil.diagnose.report import report
from hil.recording import read_recording

SHARED = Path(__file__).resolve().parents[3] / "shared" / "recordings"
ANSWERS = SHARED / "answers.json"

pytestmark = [pytest.mark.skipif(not ANSWERS.is_file(), reason="shared recordings not present"),
              pytest.mark.slow(seconds=60)]


def _answers() -> list[dict[str, Any]]:
    return list(json.loads(ANSWERS.read_text())) if ANSWERS.is_file() else []


@cache
def _report(name: str) -> dict[str, Any]:
    return report(diagnose(read_recording(SHARED / name)))


@pytest.mark.parametrize("answer", _answers(), ids=lambda a: str(a["file"]))
def test_names_the_hidden_effect_and_nothing_else(answer: dict[str, Any]) -> None:
    data = _report(answer["file"])
    assert [cause["name"] for cause in data["causes"]] == answer["effects"]
    for cause in data["causes"]:
        gain = cause["gain"]
        assert gain["significant"]
        assert gain["rms_after_nm"] < gain["rms_before_nm"]


@pytest.mark.parametrize(
    ("name", "check"),
    [
        ("example_01.csv.gz", lambda p, t: p["periods_per_rev"] == t["cog_periods"]
         and math.isclose(p["amplitude_nm"], t["cog_amp"], rel_tol=0.15)),
        ("example_02.csv.gz", lambda p, t: math.isclose(p["static_torque_nm"], t["Ts"],
                                                        rel_tol=0.15)),
        ("example_03.csv.gz", lambda p, t: math.isclose(p["mge_nm"], t["mge"], rel_tol=0.15)),
        ("example_04.csv.gz", lambda p, t: math.isclose(p["stiffness_nm_per_rad"], t["k_cable"],
                                                        rel_tol=0.15)),
        ("example_06.csv.gz", lambda p, t: math.isclose(p["resonance_hz"], t["f_res_hz"],
                                                        rel_tol=0.15)),
        ("example_07.csv.gz", lambda p, t: p["periods_per_rev"] == t["kt_periods"]
         and math.isclose(p["relative_amplitude"], t["kt_ripple"], rel_tol=0.15)),
    ],
)
def test_key_parameter(name: str, check: Any) -> None:
    truth = next(a["truth"] for a in _answers() if a["file"] == name)
    cause = _report(name)["causes"][0]
    assert check(cause["parameters"], truth), (cause["parameters"], truth)
