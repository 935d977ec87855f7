"""A run is complete or it is not PASS, and a profile is checked whole before any motion.

- A protocol subset (``-k``), a deselection or a skip leaves results the profile declares
  without a value: the run is INCOMPLETE (exit 1, never PASS), the certificate lists each
  with why; a result the profile marks ``required = false`` may be missing.
- A misspelt protocol or measurement table, a profile without protocols or results, a
  declared result whose protocol is not configured, and a misspelt protocol setting each
  stop the run with one line naming the file and the table, before the first motion.
"""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

import pytest

from hil.calibration import CalibrationRun
from hil.characterise.processes import Finished, run_command
from hil.identify.estimate import Estimate
from hil.measurement import MethodBiasMap, Outcome
from hil.profile import UnitProfile, builtin_profile_path, load_profile, profile_from_mapping
from hil.suite.catalogue import PROTOCOL_OF, PROTOCOLS

DEMO = builtin_profile_path().read_text(encoding="utf-8")


def _calibrate(tmp_path: Path, *args: str, profile_text: str | None = None
               ) -> Finished:
    command = ["calibrate", "--drive", "sim",
               "--unit-serial", "K-2", "--out", str(tmp_path / "out")]
    if profile_text is not None:
        path = tmp_path / "unit.toml"
        path.write_text(profile_text, encoding="utf-8")
        command += ["--profile", str(path)]
    return run_command([*command, "--", "--store", "off", "--no-documents", *args],
                       timeout_s=600)


def _certificate(tmp_path: Path) -> dict:  # type: ignore[type-arg]
    return json.loads((tmp_path / "out" / "K-2" / "certificate.json").read_text())


def test_a_protocol_subset_is_incomplete_never_pass(tmp_path: Path) -> None:
    done = _calibrate(tmp_path, "-k", "current_loop")
    assert done.returncode == 1, done.stdout[-2000:]
    cert = _certificate(tmp_path)
    assert cert["outcome"] == "INCOMPLETE"
    assert [r["parameter"] for r in cert["results"]] == ["current_loop_time_constant_ms"]
    missing = {m["parameter"]: m for m in cert["not_measured"]}
    assert set(missing) == set(load_profile(None).measurements) - {
        "current_loop_time_constant_ms"}
    assert all(m["required"] for m in missing.values())
    assert "did not run" in missing["inertia_kg_m2"]["reason"]
    assert "INCOMPLETE" in (tmp_path / "out" / "K-2" / "certificate.txt").read_text()
    assert "unit K-2: INCOMPLETE" in done.stdout


def test_results_marked_optional_may_be_missing(tmp_path: Path) -> None:
    optional = re.sub(r"^(\[measurements\.(?!current_loop_time_constant_ms\])\w+\])$",
                      r"\1\nrequired = false", DEMO, flags=re.M)
    done = _calibrate(tmp_path, "-k", "current_loop", profile_text=optional)
    assert done.returncode == 0, done.stdout[-2000:]
    cert = _certificate(tmp_path)
    assert cert["outcome"] == "PASS"
    assert cert["not_measured"]
    assert not any(m["required"] for m in cert["not_measured"])


def _run(profile_text: str, *, protocol: str, skipped: bool) -> CalibrationRun:
    run = CalibrationRun(profile=_profile(profile_text), unit_serial="U-1",
                         out_dir=Path("unused"), drive_kind="sim",
                         method_bias=MethodBiasMap(source="off", sha256="", entries={}))
    run.expected = {name: PROTOCOL_OF[name] for name in run.profile.measurements}
    for name, parameter in run.expected.items():
        if parameter != protocol:
            spec = run.profile.measurement(name)
            run.record(parameter, Estimate(name=name, value=spec.nominal, unit=spec.unit,
                                           standard_uncertainty=0.0))
    if skipped:
        run.report_skip(protocol, "the station has no shaft torque sensor")
    return run


def _profile(text: str) -> UnitProfile:
    return profile_from_mapping(tomllib.loads(text), source="unit.toml")


def test_a_skipped_required_result_makes_the_run_incomplete() -> None:
    run = _run(DEMO, protocol="torque_constant", skipped=True)
    assert run.overall_outcome(aborted=False) == Outcome.INCOMPLETE
    (reason,) = {m.reason for m in run.not_measured()}
    assert "no shaft torque sensor" in reason
    optional = DEMO.replace("[measurements.torque_constant_nm_a]",
                            "[measurements.torque_constant_nm_a]\nrequired = false")
    run = _run(optional, protocol="torque_constant", skipped=True)
    assert run.overall_outcome(aborted=False) == Outcome.INCOMPLETE  # three others required


BAD_PROFILES = {
    "misspelt protocol table": (
        DEMO.replace("[protocols.stribeck]", "[protocols.stribek]"),
        "[protocols.stribek]: no such protocol (did you mean 'stribeck'?)"),
    "unknown protocol table": (
        DEMO + "\n[protocols.no_such_protocol]\n", "[protocols.no_such_protocol]: no such"),
    "misspelt measurement table": (
        DEMO.replace("[measurements.static_friction_nm]", "[measurements.static_friction_mn]"),
        "no protocol measures 'static_friction_mn' (did you mean 'static_friction_nm'?)"),
    "misspelt protocol setting": (
        DEMO.replace("[protocols.stribeck]", "[protocols.stribeck]\nspeeds_rad_sx = [0.1]"),
        "[protocols.stribeck] has an unknown setting 'speeds_rad_sx'"),
    "no protocol tables": (
        re.sub(r"^\[protocols\.\w+\]\n(?:(?!\[).*\n)*", "", DEMO, flags=re.M),
        "configures no protocol"),
    "no measurement tables": (
        re.sub(r"^\[measurements\.\w+\]\n(?:(?!\[).*\n)*", "", DEMO, flags=re.M),
        "declares no result"),
    "a result whose protocol is not configured": (
        re.sub(r"^\[protocols\.stribeck\]\n(?:(?!\[).*\n)*", "", DEMO, flags=re.M),
        "[measurements.static_friction_nm]: measured by protocol 'stribeck', which the "
        "profile does not configure"),
}


@pytest.mark.parametrize("case", sorted(BAD_PROFILES))
def test_a_bad_profile_stops_before_any_motion_in_one_line(tmp_path: Path, case: str) -> None:
    text, expected = BAD_PROFILES[case]
    done = _calibrate(tmp_path, profile_text=text)
    assert done.returncode == 4, done.stdout[-2000:] + done.stderr[-2000:]
    errors = [line for line in done.stderr.splitlines() if line.startswith("ERROR:")]
    assert len(errors) == 1, done.stderr
    assert expected in errors[0]
    assert "unit.toml" in errors[0]
    assert "Traceback" not in done.stdout + done.stderr
    assert not (tmp_path / "out" / "K-2").exists(), "something moved or was written"


def test_the_catalogue_knows_every_protocol_of_the_suite() -> None:
    suite = Path(__file__).resolve().parents[1] / "protocols"
    marked = set()
    for module in suite.glob("test_*.py"):
        names = re.findall(r"^from hil\.suite\.(\w+) import", module.read_text(), flags=re.M)
        marked.add(module.stem.removeprefix("test_"))
        assert module.stem.removeprefix("test_") in names, module
    assert marked == set(PROTOCOLS)
    both = set(load_profile("demo_gimbal_elevation").measurements) | set(
        load_profile("demo_gimbal_azimuth").measurements)
    assert both <= set(PROTOCOL_OF)
