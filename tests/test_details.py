"""Issue 25, a typed record: each protocol's details are a dataclass written to JSON and read
back by one reader (:mod:`hil.details`); a key that does not read as the declared field is
refused naming the protocol and the key, and the documents say which plot it cost."""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from hil.characterise.processes import run_command
from hil.details import Details, DetailsError, RunDetails
from hil.identify.gravity_cable import CableLoop
from hil.report.data import from_certificate
from hil.report.documents import write_documents
from hil.suite.catalogue import CATALOGUE
from hil.suite.inertia_friction import InertiaFrictionDetails, SineComponent
from hil.suite.stribeck import CrossCheck, FrictionPoint, StribeckDetails
from tests.helpers import subset_profile


def test_every_protocol_declares_frozen_details() -> None:
    for name, protocol in CATALOGUE.items():
        kind = protocol.details
        assert issubclass(kind, Details), name
        assert dataclasses.is_dataclass(kind), name
        assert kind.__dataclass_params__.frozen, name  # type: ignore[attr-defined]


def _stribeck() -> StribeckDetails:
    return StribeckDetails(
        runs=2, stop_rule="max_runs = 2", recorded_rows=10, coulomb_nm=0.02,
        viscous_nm_s_rad=0.005, residual_rms_nm=1e-5, kt_ripple_correction="none",
        lowest_clean_speed_rad_s=math.nan, stick_slip_speeds_rad_s=(0.001,),
        points=(FrictionPoint(speed_rad_s=0.1, friction_nm=0.021, friction_u_nm=None,
                              stick_slip=False),),
        cross_check_sine={"coulomb_nm": CrossCheck(stribeck=0.02, sine=0.021,
                                                   normalised_error=0.4)},
        note="a note")


def test_details_come_back_as_they_were_written() -> None:
    written = _stribeck()
    text = json.dumps(written.to_json())
    read = StribeckDetails.from_json(json.loads(text), where="stribeck")
    assert math.isnan(read.lowest_clean_speed_rad_s)
    assert dataclasses.replace(read, lowest_clean_speed_rad_s=0.0) == dataclasses.replace(
        written, lowest_clean_speed_rad_s=0.0)
    assert isinstance(read.points, tuple)
    assert isinstance(read.points[0], FrictionPoint)
    friction = InertiaFrictionDetails(
        runs=1, stop_rule="one run", method="least_squares", frequency_hz=2.0,
        settle_periods=1, centre_rad=0.1, load_stiffness_nm_rad=None,
        cable_loop_removed=CableLoop(half_width_nm=0.001, half_width_u_nm=1e-4,
                                     angle_rad=0.02),
        current_loop_lag_compensated_s=2e-4, position_torque_removed="none", fit_pct=97.5,
        noise_rms_nm=0.004,
        components=(SineComponent(velocity_amplitude_rad_s=0.5, quadrature_c_nm=0.02,
                                  in_phase_s_nm=0.03, periods=5),))
    assert InertiaFrictionDetails.from_json(
        json.loads(json.dumps(friction.to_json())), where="inertia_friction") == friction


@pytest.mark.parametrize(("change", "message"), [
    (lambda d: d.update(coulomb_nmm=d.pop("coulomb_nm")),
     r"stribeck: unknown key\(s\) coulomb_nmm"),
    (lambda d: d.pop("viscous_nm_s_rad"), r"stribeck: key viscous_nm_s_rad missing"),
    (lambda d: d.update(runs="2"), r"stribeck\.runs: an integer expected"),
    (lambda d: d["points"][0].update(speed_rad_s="fast"), r"stribeck\.points\[0\]\.speed_rad_s"),
    (lambda d: d.update(stick_slip_speeds_rad_s=3), r"stick_slip_speeds_rad_s: a list expected"),
])
def test_details_that_do_not_read_are_refused_naming_the_key(
        change: Callable[[dict[str, Any]], object], message: str) -> None:
    raw = json.loads(json.dumps(_stribeck().to_json()))
    change(raw)
    with pytest.raises(DetailsError, match=message):
        StribeckDetails.from_json(raw, where="stribeck")


def test_a_field_with_a_default_may_be_absent() -> None:
    @dataclasses.dataclass(frozen=True, slots=True, kw_only=True)
    class Later(RunDetails):
        added_later_s: float = 0.5

    read = Later.from_json({"runs": 1, "stop_rule": "one run"}, where="later")
    assert read.added_later_s == 0.5


def test_a_certificate_with_a_renamed_detail_costs_that_plot_and_says_so(
        tmp_path: Path) -> None:
    profile = subset_profile(tmp_path / "profiles", "current_loop", "inertia_friction")
    done = run_command(["calibrate", "--drive", "sim", "--profile", str(profile),
                        "--unit-serial", "DET-1", "--out", str(tmp_path / "out"), "--",
                        "--no-documents", "--store", "off"])
    assert done.returncode == 0, done.stdout + done.stderr
    unit = tmp_path / "out" / "DET-1"
    path = unit / "certificate.json"
    cert = json.loads(path.read_text(encoding="utf-8"))
    points = cert["method"]["details"]["current_loop"]
    points["lag_points"] = points.pop("points")
    path.write_text(json.dumps(cert), encoding="utf-8")
    data = {d.name: d for d in from_certificate(cert, unit)}
    assert data["current_loop"].details is None
    assert "unknown key(s) lag_points" in data["current_loop"].details_problem
    assert data["inertia_friction"].details is not None
    problems = write_documents(path)
    assert [p for p in problems if "current_loop" in p] == [
        "plot of current_loop not drawn: DetailsError: the certificate's details of "
        "current_loop: unknown key(s) lag_points"]
    assert not [p for p in problems if "inertia_friction" in p]
