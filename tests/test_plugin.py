"""End to end through pytest: protocols on the simulated drive produce a certificate."""

from __future__ import annotations

import hashlib
import json
import math
import re
from pathlib import Path

import pytest

# loaded here, outside the in-process runs: pytester restores sys.modules after each, and
# SQLAlchemy imported afresh inside a second run finds its compiled caches from the first
# ("'InternalTraversal' object is not callable"); the store is imported lazily since the
# command line loads each command's dependencies when it runs
import hil.store.record  # noqa: F401
from hil.certificate.controller import controller_outputs
from hil.certificate.model import read_certificate
from hil.profile import builtin_profile_path, load_profile
from tests.compare import certificate_factory as factory
from tests.helpers import subset_profile

pytest_plugins = ["pytester"]


def _run(pytester: pytest.Pytester, out: Path, *args: str) -> pytest.RunResult:
    """The J/B/T_c protocol alone, on a profile of a unit type that needs only it."""
    profile = ([] if "--profile" in args
               else ["--profile", str(subset_profile(pytester.path, "inertia_friction"))])
    return pytester.runpytest_inprocess(
        *profile,
        "--pyargs",
        "gimbal_hil_protocols.test_inertia_friction",
        "-p",
        "no:cacheprovider",
        "--out",
        str(out),
        *args,
    )


def _counts(result: pytest.RunResult) -> dict[str, int]:
    outcomes = result.parseoutcomes()
    return {key: outcomes.get(key, 0) for key in ("passed", "failed", "errors")}


def _profile_with(tmp_path: Path, old: str, new: str) -> Path:
    text = builtin_profile_path().read_text(encoding="utf-8")
    assert old in text
    path = tmp_path / "unit.toml"
    path.write_text(text.replace(old, new), encoding="utf-8")
    return path


def test_calibration_writes_a_passing_certificate(
    pytester: pytest.Pytester, tmp_path: Path
) -> None:
    out = tmp_path / "certs"
    result = _run(pytester, out, "--unit-serial", "GMB-0042")
    assert result.ret == 0
    assert _counts(result)["passed"] >= 4
    cert = json.loads((out / "GMB-0042" / "certificate.json").read_text())
    assert cert["outcome"] == "PASS"
    assert cert["unit"]["serial"] == "GMB-0042"
    assert re.fullmatch(r"GMB-0042-\d{8}T\d{6}Z-[0-9a-f]{8}", cert["certificate_id"])
    assert len(cert["method"]["profile_sha256"]) == 64
    assert cert["software"]["version"]
    params = {r["parameter"]: r for r in cert["results"]}
    assert {"inertia_kg_m2", "viscous_nm_s_rad", "coulomb_nm"} <= set(params)
    for r in params.values():
        assert r["expanded_uncertainty"] == pytest.approx(
            r["coverage_factor"] * r["standard_uncertainty"]
        )
        assert r["lower_limit"] <= r["value"] <= r["upper_limit"]
        # the budget is what u is made of: its contributions add in quadrature to u
        lines = r["budget"]
        assert lines[0]["type"] == "A"
        assert math.hypot(*(line["contribution"] for line in lines)) == pytest.approx(
            r["standard_uncertainty"]
        )
    assert any(line["component"].startswith("method: error over") for line in
               params["inertia_kg_m2"]["budget"])
    assert len(cert["method"]["method_bias"]["sha256"]) == 64
    assert "Uncertainty budgets" in (out / "GMB-0042" / "certificate.txt").read_text()
    plant = load_profile().plant
    assert plant is not None
    # torque-based results are in the drive's reported-torque units (what the loop commands)
    expected = plant.inertia_kg_m2 / (1 + plant.torque_constant_error_rel)
    assert params["inertia_kg_m2"]["value"] == pytest.approx(expected, rel=0.04)
    for raw in cert["raw_data"]:
        path = out / "GMB-0042" / raw["file"]
        assert path.is_file()
        assert hashlib.sha256(path.read_bytes()).hexdigest() == raw["sha256"]
    # the banner line at the top and the conformity statement at the end
    assert (out / "GMB-0042" / "certificate.txt").read_text().count("OUTCOME: PASS") == 2
    controller = json.loads((out / "GMB-0042" / "controller.json").read_text())
    assert controller["certificate_id"] == cert["certificate_id"]
    assert controller["friction_feedforward"]["coulomb_nm"] == params["coulomb_nm"]["value"]
    assert "cable_feedforward" not in controller  # gravity_cable did not run here
    listed = {a["file"]: a["sha256"] for a in cert["artifacts"]}
    assert (
        listed["controller.json"]
        == hashlib.sha256((out / "GMB-0042" / "controller.json").read_bytes()).hexdigest()
    )
    assert cert["machine_time"]["motion_time_s"] > 0


def test_a_tolerance_miss_fails_the_certificate(pytester: pytest.Pytester, tmp_path: Path) -> None:
    """The demo unit's J is 0.0036; a profile expecting 0.0050 ± 10 % must not pass it."""
    profile = _profile_with(
        tmp_path, "nominal = 0.0036\ntolerance_pct = 15", "nominal = 0.0050\ntolerance_pct = 10"
    )
    out = tmp_path / "certs"
    result = _run(pytester, out, "--profile", str(profile))
    assert _counts(result)["failed"] == 1
    assert result.ret == 1
    cert = json.loads((out / "SIM-0001" / "certificate.json").read_text())
    assert cert["outcome"] == "FAIL"
    inertia = next(r for r in cert["results"] if r["parameter"] == "inertia_kg_m2")
    assert inertia["outcome"] == "FAIL"


def test_an_infrastructure_error_never_passes(pytester: pytest.Pytester, tmp_path: Path) -> None:
    """A command beyond the unit's velocity limit is refused before motion: ERROR."""
    profile = _profile_with(tmp_path, "velocity_rad_s = 3.0", "velocity_rad_s = 0.8")
    out = tmp_path / "certs"
    result = _run(pytester, out, "--profile", str(profile))
    assert result.ret != 0
    cert = json.loads((out / "SIM-0001" / "certificate.json").read_text())
    assert cert["outcome"] == "ERROR"
    assert cert["method"]["protocols"]["inertia_friction"]["outcome"] == "ERROR"
    assert "exceeds" in " ".join(cert["method"]["protocols"]["inertia_friction"]["messages"])


def test_recalibration_keeps_the_previous_certificate(
    pytester: pytest.Pytester, tmp_path: Path
) -> None:
    out = tmp_path / "certs"
    assert _run(pytester, out).ret == 0
    first = json.loads((out / "SIM-0001" / "certificate.json").read_text())["certificate_id"]
    assert _run(pytester, out, "--seed", "3").ret == 0
    second = json.loads((out / "SIM-0001" / "certificate.json").read_text())["certificate_id"]
    assert first != second
    kept = list((out / "SIM-0001" / "history").glob("*/certificate.json"))
    assert [json.loads(p.read_text())["certificate_id"] for p in kept] == [first]


def test_bad_profile_is_a_usage_error(pytester: pytest.Pytester, tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[unit]\ntype = 'x'\n", encoding="utf-8")
    result = _run(pytester, tmp_path / "certs", "--profile", str(bad))
    assert result.ret != 0
    assert "missing table [limits]" in "\n".join(result.outlines + result.errlines)


def test_allure_report_carries_the_judged_measurements(
    pytester: pytest.Pytester, tmp_path: Path
) -> None:
    allure_dir = tmp_path / "allure"
    result = _run(pytester, tmp_path / "certs", "--alluredir", str(allure_dir))
    assert result.ret == 0
    attached = [json.loads(p.read_text()) for p in allure_dir.glob("*-attachment.json")]
    assert {a["parameter"] for a in attached} >= {"inertia_kg_m2", "coulomb_nm"}
    assert all(a["outcome"] == "PASS" for a in attached)


def test_a_typo_in_protocol_settings_is_an_error_not_a_default(
    pytester: pytest.Pytester, tmp_path: Path
) -> None:
    profile = _profile_with(
        tmp_path, "settle_periods = 1\nperiods = 5", "settle_period = 1\nperiods = 5"
    )
    """Found when the profile is checked, before the first motion (it was found when the
    protocol read its settings, after the protocols before it had moved)."""
    out = tmp_path / "certs"
    result = _run(pytester, out, "--profile", str(profile))
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    (error,) = [line for line in result.stderr.lines if line.startswith("ERROR:")]
    assert "unknown setting 'settle_period' (did you mean 'settle_periods'?)" in error
    assert str(profile) in error
    assert not (out / "SIM-0001" / "certificate.json").exists()


def test_controller_outputs_carry_the_cable_loop_when_measured() -> None:
    document = factory.certificate(results=[
        factory.result("coulomb_nm", 0.02, u_a=0.001),
        factory.result("cable_stiffness_nm_rad", 0.004, u_a=0.0001),
        factory.result("cable_hysteresis_nm", 0.001, u_a=0.0001),
    ])
    outputs = controller_outputs(read_certificate(document))
    assert outputs is not None
    assert outputs["certificate_id"] == document["certificate_id"]
    assert outputs["cable_feedforward"] == {"stiffness_nm_rad": 0.004, "hysteresis_nm": 0.001}
    assert outputs["friction_feedforward"] == {"coulomb_nm": 0.02}


def test_a_real_drive_without_a_serial_is_a_usage_error(pytester: pytest.Pytester) -> None:
    result = pytester.runpytest_inprocess(
        "--pyargs", "gimbal_hil_protocols.test_inertia_friction", "-p", "no:cacheprovider",
        "--drive", "canopen",
    )
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines(["*--drive canopen (a real unit) needs --unit-serial SERIAL*"])


def test_the_sines_run_again_while_a_result_misses_its_share_of_the_tolerance(
    pytester: pytest.Pytester, tmp_path: Path
) -> None:
    """stop_at_u_fraction: T_c's U (about 0.0003 N·m) never reaches 0.01 × its ±0.006 N·m
    half-width: the sines run max_runs times, pooled, and the certificate says why (one run
    when U is reached: tests/test_stop_rule.py)."""
    fraction, runs = 0.01, 2
    profile = _profile_with(
        tmp_path, "settle_periods = 1\nperiods = 5",
        f"settle_periods = 1\nperiods = 5\nstop_at_u_fraction = {fraction}\nmax_runs = 2\n"
        'stop_results = "coulomb_nm"')
    out = tmp_path / "certs"
    # in a subprocess: a second in-process calibration re-imports the numba kernel's
    # typing registrations ("cannot augment Function(eq)"), whatever ran before
    pytester.runpytest_subprocess(
        "--pyargs", "gimbal_hil_protocols.test_inertia_friction", "-p", "no:cacheprovider",
        "--out", str(out), "--profile", str(profile), "--store", "off", "--no-documents")
    cert = json.loads((out / "SIM-0001" / "certificate.json").read_text())
    details = cert["method"]["details"]["inertia_friction"]
    sines = [f for f in cert["raw_data"] if f["excitation"].startswith("sine_")]
    assert details["runs"] == runs
    assert len(sines) == 2 * runs
    coulomb = next(r for r in cert["results"] if r["parameter"] == "coulomb_nm")
    assert details["stop_rule"].startswith("max_runs = 2 reached with coulomb_nm U = ")
    assert coulomb["budget"][0]["component"].endswith("mean of 2 runs")
