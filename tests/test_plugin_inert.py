"""The ``pytest11`` entry point stays out of other projects' test runs: no profile read, no
fixture around their tests, until a calibration option is given or the suite is collected."""

from __future__ import annotations

import pytest

pytest_plugins = ["pytester"]

PROBE = """
def test_probe(request):
    active = request.config.pluginmanager.get_plugin("gimbal-hil-calibration") is not None
    print(f"ACTIVE={active} FIXTURES={sorted(request.fixturenames)}")
"""


def _probe(pytester: pytest.Pytester, *args: str) -> str:
    pytester.makepyfile(test_other_project=PROBE)
    result = pytester.runpytest_subprocess("-s", "-p", "no:cacheprovider", *args)
    assert result.ret == 0, result.stdout.str()
    (line,) = [x for x in result.stdout.lines if "ACTIVE=" in x]
    return line[line.index("ACTIVE=") :]


def test_another_projects_run_does_not_see_the_calibration(pytester: pytest.Pytester) -> None:
    line = _probe(pytester)
    assert line.startswith("ACTIVE=False")
    assert "FIXTURES=['request']" in line  # nothing autouse wrapped the test


@pytest.mark.parametrize("option", [["--drive", "sim"], ["--profile", "demo_gimbal_elevation"]])
def test_a_calibration_option_activates_it(pytester: pytest.Pytester, option: list[str]) -> None:
    assert _probe(pytester, *option).startswith("ACTIVE=True")


def test_collecting_the_suite_activates_it(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_other_project=PROBE)
    result = pytester.runpytest_subprocess(
        "-p", "no:cacheprovider", "--collect-only", "-q", "--pyargs", "gimbal_hil_protocols"
    )
    assert result.ret == 0, result.stdout.str()
    assert any("test_inertia_friction" in line for line in result.stdout.lines)


def test_a_bad_profile_option_is_one_line_before_collection(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_other_project=PROBE)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "--profile", "no_such_unit")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    errors = [line for line in result.stderr.lines if line.startswith("ERROR:")]
    assert len(errors) == 1, result.stderr.str()
    assert "no_such_unit" in errors[0]
    assert "Traceback" not in result.stderr.str() + result.stdout.str()
