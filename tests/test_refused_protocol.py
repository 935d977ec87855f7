"""A protocol the drive or its link refuses (a loaded host behind the Modbus setpoint lead,
say) says so once, in one line, and the certificate says why: no traceback, and not one
copy of the sentence per result of the protocol."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest_plugins = ["pytester"]

MESSAGE = ("modbus tcp 127.0.0.1:5020 unit 1: 'sine_2hz_1rad_s': the host fell behind the "
           "setpoint lead (3 periods)")

REFUSED_PROTOCOL = f'''
import pytest
from hil.errors import DriveCommunicationError

pytestmark = pytest.mark.protocol("inertia_friction")


@pytest.fixture(scope="module")
def result(calibration):
    raise DriveCommunicationError("{MESSAGE}")


@pytest.mark.parametrize("parameter", ["inertia_kg_m2", "viscous_nm_s_rad", "coulomb_nm"])
def test_inertia_friction(parameter, result):
    pass
'''


def test_a_refused_protocol_says_so_once_in_one_line(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_refused=REFUSED_PROTOCOL)
    out = pytester.path / "out"
    result = pytester.runpytest_subprocess(
        "-p", "no:cacheprovider", "-q", "--drive", "sim", "--out", str(out),
        "--store", "off", "--no-documents")
    text = result.stdout.str() + result.stderr.str()
    assert result.ret == pytest.ExitCode.TESTS_FAILED, text
    # once, besides pytest's own index of errors at the end (its short test summary, which
    # repeats each error's first line: cut to the terminal's width, whole under CI=true)
    told = [line for line in text.splitlines()
            if "the host fell behind" in line and not line.startswith("ERROR test_refused.py")]
    assert len(told) == 1, text
    assert "Traceback" not in text, text
    assert "\nE   " not in text, text
    assert "1 error" in text, text
    assert "2 skipped" in text, text
    certificate = json.loads((out / "SIM-0001" / "certificate.json").read_text())
    assert certificate["outcome"] == "ERROR"
    assert MESSAGE in Path(out / "SIM-0001" / "certificate.txt").read_text()


def test_a_bug_keeps_its_traceback(pytester: pytest.Pytester) -> None:
    """Only the harness's own refusals are shortened: an unexpected exception is a bug and
    shows where it happened."""
    pytester.makepyfile(test_refused=REFUSED_PROTOCOL.replace(
        f'raise DriveCommunicationError("{MESSAGE}")', 'raise KeyError("no_such_key")'))
    result = pytester.runpytest_subprocess(
        "-p", "no:cacheprovider", "-q", "--drive", "sim", "--out",
        str(pytester.path / "out"), "--store", "off", "--no-documents")
    assert result.ret == pytest.ExitCode.TESTS_FAILED
    assert "KeyError" in result.stdout.str()
    assert "3 errors" in result.stdout.str()
