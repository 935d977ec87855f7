"""Measured data nobody here produced: EMPS (linear axis) and an ODrive cogging run."""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path
from typing import Any

import pytest

from hil.diagnose.core import diagnose
from hil.diagnose.report import model_parameters, report
from hil.recording import read_recording

REAL = Path(__file__).resolve().parents[3] / "shared" / "real-data"
EMPS_TRAIN = REAL / "emps_train.csv.gz"
EMPS_PULSES = REAL / "emps_pulses.csv.gz"
ODRIVE = REAL / "odrive_slow003_nocomp.csv.gz"

# Janot, Gautier, Brunot (2019): IDIM-LS fit of F = M·a + Fv·v + Fc·sgn(v) + offset
PUBLISHED = {"inertia_kg_m2": 95.1089, "viscous_nm_s_rad": 203.5034, "coulomb_nm": 20.3935,
             "offset.offset_nm": -3.1648}


@cache
def _emps() -> dict[str, Any]:
    diagnosis = diagnose(read_recording(EMPS_TRAIN), validate=read_recording(EMPS_PULSES))
    data = report(diagnosis)
    offset = next(c for c in diagnosis.selection.rounds[0] if c.effect == "offset")
    data["offset_alone"] = model_parameters(offset.fit)
    return data


@pytest.mark.skipif(not EMPS_PULSES.is_file(), reason="EMPS data not present")
def test_emps_offset_alone_reproduces_published_model() -> None:
    """The published symmetric model with its offset: the offset is the first candidate."""
    data = _emps()
    assert data["axis_kind"] == "linear"
    assert data["units"]["effort (every *_nm)"] == "N"
    offset = next(c for c in data["candidates_by_round"][0] if c["name"] == "offset")
    assert offset["gain"]["significant"]
    model = data["offset_alone"]
    for name, published in PUBLISHED.items():
        assert math.isclose(model[name], published, rel_tol=0.02), (name, model[name])


def _interval_holds(cause: dict[str, Any], name: str) -> tuple[float, float]:
    low, high = cause["uncertainty"][name]["ci95"]
    assert low < cause["parameters"][name] < high, name
    return low, high


@pytest.mark.skipif(not EMPS_PULSES.is_file(), reason="EMPS data not present")
def test_emps_names_asymmetric_friction_and_the_offset_with_intervals() -> None:
    """Both causes, each with its 95 % interval: the viscous asymmetry the data identify
    on their own, and the constant, an offset that is not separable from a Coulomb
    difference between the directions (one column while moving, ΔT_c = −2 × offset)."""
    data = _emps()
    names = [cause["name"] for cause in data["causes"]]
    assert names == ["asymmetric_friction", "offset"], names
    friction, offset = data["causes"]
    parameters = friction["parameters"]
    # the published asymmetric fit: Fv+ 166.7, Fv- 240.4 N s/m
    assert math.isclose(parameters["viscous_pos"], 166.7, rel_tol=0.05)
    assert math.isclose(parameters["viscous_neg"], 240.4, rel_tol=0.05)
    for name in ("coulomb_pos_nm", "coulomb_neg_nm", "viscous_pos", "viscous_neg"):
        _interval_holds(friction, name)
    # the Coulomb difference is the offset's: the friction keeps the mean in both directions
    assert parameters["coulomb_pos_nm"] == parameters["coulomb_neg_nm"]
    assert "offset" in friction["note"]
    assert offset["part_of"] == "asymmetric_friction"
    assert offset["separable"] is False
    assert "power stage off" in offset["note"]
    low, high = _interval_holds(offset, "offset_nm")
    d_low, d_high = _interval_holds(offset, "coulomb_difference_nm")
    assert math.isclose(offset["parameters"]["coulomb_difference_nm"],
                        -2.0 * offset["parameters"]["offset_nm"])
    assert math.isclose(d_low, -2.0 * high)
    assert math.isclose(d_high, -2.0 * low)
    # the published -3.16 N is how a symmetric viscous term absorbs Fv- > Fv+: what is
    # left once the asymmetry is modelled is a few tenths of a newton
    assert high - low < 2.0
    assert abs(offset["parameters"]["offset_nm"]) < 1.0
    # its held-out gain is reported as measured: the pulses do not need the constant
    assert offset["gain"]["significant"] is False


@pytest.mark.skipif(not EMPS_PULSES.is_file(), reason="EMPS data not present")
def test_emps_every_named_cause_shows_heldout_gain() -> None:
    data = _emps()
    assert data["validate"] is not None
    for cause in data["causes"]:
        if "part_of" in cause:  # a part of the cause before it, judged with it
            continue
        gain = cause["gain"]
        assert gain["rms_reduction"] >= 0.01, cause["name"]
        assert gain["fit_after_pct"] > gain["fit_before_pct"]


@pytest.mark.skipif(not ODRIVE.is_file(), reason="ODrive data not present")
def test_odrive_names_cogging_with_its_orders() -> None:
    data = report(diagnose(read_recording(ODRIVE)))
    assert data["causes"][0]["name"] == "cogging"
    parameters = data["causes"][0]["parameters"]
    orders = [row["periods_per_rev"] for row in parameters["orders"]]
    assert parameters["periods_per_rev"] == orders[0]
    assert len(orders) >= 3
    assert any(i["kind"] == "irregular_sampling" for i in data["data_issues"])
    # the logged position is the drive's interpolated estimate, finer than the 8192 counts
    assert any(i["kind"] == "quantisation" for i in data["data_issues"])
