"""``gimbal-hil calibrate … -- --junitxml FILE``: the JUnit XML names the unit (suite name
and properties from its certificate) and carries each judged measurement as properties of
its test case, read back with xml.etree as a CI dashboard or a line MES tool would."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from hil.profile import builtin_profile_path
from tests.report.runs import calibrate

FIELDS = {"value": "value", "U": "expanded_uncertainty", "unit": "unit",
          "lower_limit": "lower_limit", "upper_limit": "upper_limit", "outcome": "outcome"}


@dataclass(frozen=True)
class Junit:
    suite: ET.Element
    cert: dict[str, Any]


def _run(out: Path, serial: str, *pytest_args: str, profile: Path | None = None) -> Junit:
    args = ["--profile", str(profile)] if profile is not None else []
    run = calibrate(out, serial, *args, "--", "--store", "off", "--no-documents",
                    "--junitxml", str(out / "j.xml"), *pytest_args)
    assert run.returncode in (0, 1), run.stdout
    (suite,) = ET.parse(out / "j.xml").getroot().iter("testsuite")
    cert = json.loads((run.unit_dir / "certificate.json").read_text(encoding="utf-8"))
    return Junit(suite=suite, cert=cert)


def properties(element: ET.Element) -> dict[str, str]:
    found = element.find("properties")
    return {} if found is None else {p.get("name", ""): p.get("value", "")
                                     for p in found.iter("property")}


@pytest.fixture(scope="module")
def junit(tmp_path_factory: pytest.TempPathFactory) -> Junit:
    """The current loop (made to FAIL: a profile expecting a slower loop) and standstill."""
    out = tmp_path_factory.mktemp("junit")
    text = builtin_profile_path().read_text(encoding="utf-8")
    old = "[measurements.current_loop_time_constant_ms]\nunit = \"ms\"\nnominal = 0.3\n"
    assert old in text
    profile = out / "line7_unit.toml"
    profile.write_text(text.replace(old, old.replace("0.3", "0.6")), encoding="utf-8")
    return _run(out, "J-1", "-k", "current_loop or standstill", profile=profile)


def test_the_suite_is_named_after_the_unit(junit: Junit) -> None:
    assert junit.suite.get("name") == "gimbal-hil J-1"


def test_the_suite_carries_the_certificates_identity(junit: Junit) -> None:
    found = properties(junit.suite)
    assert found["unit_serial"] == "J-1"
    assert found["profile"] == "line7_unit"
    assert found["certificate_id"] == junit.cert["certificate_id"]
    assert found["outcome"] == junit.cert["outcome"] == "FAIL"
    assert found["unit_type"] == junit.cert["unit"]["type"]
    assert found["profile_sha256"] == junit.cert["method"]["profile_sha256"]


def test_each_test_case_carries_its_measurement(junit: Junit) -> None:
    results = {r["parameter"]: r for r in junit.cert["results"]}
    assert set(results) == {"current_loop_time_constant_ms", "standstill_torque_ripple_mnm",
                            "standstill_jitter_urad"}
    seen = set()
    for case in junit.suite.iter("testcase"):
        parameter = case.get("name", "").partition("[")[2].rstrip("]")
        found = properties(case)
        assert {name.partition(".")[0] for name in found} == {parameter}, case.get("name")
        for field, key in FIELDS.items():
            expected = results[parameter][key]
            got = found[f"{parameter}.{field}"]
            if isinstance(expected, float):
                assert float(got) == expected, (parameter, field)
            else:
                assert got == str(expected), (parameter, field)
        seen.add(parameter)
    assert seen == set(results)
    assert results["current_loop_time_constant_ms"]["outcome"] == "FAIL"  # judged all the same


def test_a_suite_name_the_user_set_is_kept(tmp_path: Path) -> None:
    found = _run(tmp_path, "J-2", "-k", "standstill", "-o", "junit_suite_name=line-7")
    assert found.suite.get("name") == "line-7"
    assert properties(found.suite)["unit_serial"] == "J-2"
