"""The README's first command as a new user runs it: without the test extras, from the
repository root or from any folder, whatever ``conftest.py`` or pytest configuration lies
there; and the project's own test run writes nowhere the user keeps results."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow(seconds=30)  # scheduled early (conftest.py)

REPOSITORY = Path(__file__).resolve().parents[1]

# What `pip install -e .` alone leaves out: the test extras. A package of that name on the
# path that refuses to import stands in for their absence; Hypothesis's own pytest plugin,
# installed here with the extras and absent there, is not loaded (`-p no:hypothesispytest`).
# .ci/run runs the command itself in a fresh environment without the extras.
MISSING_EXTRA = "raise ModuleNotFoundError(\"No module named 'hypothesis'\", name='hypothesis')\n"
HOSTILE_CONFTEST = "raise RuntimeError('the operator folder conftest.py was imported')\n"
HOSTILE_CONFIG = "[pytest]\naddopts = --no-such-option-from-the-operator-folder\n"


def _without_test_extras(tmp_path: Path) -> dict[str, str]:
    shadow = tmp_path / "no-test-extras"
    (shadow / "hypothesis").mkdir(parents=True)
    (shadow / "hypothesis" / "__init__.py").write_text(MISSING_EXTRA)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("GIMBAL_HIL_", "PYTEST_"))}
    return {**env, "PYTHONPATH": str(shadow)}


def _calibrate(
    cwd: Path, env: dict[str, str], out: Path, *extra: str, gimbal: str | None = None
) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "hil.cli", "calibrate",
               *(("--gimbal", gimbal) if gimbal else ()), "--drive", "sim",
               "--unit-serial", "DEMO-0001", "--out", str(out), "--",
               "-p", "no:hypothesispytest", *extra]
    return subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=600, check=False)


@pytest.mark.slow
def test_the_first_command_runs_from_the_repository_root_without_the_test_extras(
    tmp_path: Path,
) -> None:
    env = _without_test_extras(tmp_path)
    probe = subprocess.run([sys.executable, "-c", "import hypothesis"], env=env,
                           capture_output=True, text=True, check=False)
    assert probe.returncode != 0, "the stand-in for missing test extras did not take"
    out = tmp_path / "certificates"
    result = _calibrate(REPOSITORY, env, out, "--store", "off", gimbal="demo_gimbal")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    gimbal = json.loads((out / "DEMO-0001" / "gimbal-certificate.json").read_text())
    assert gimbal["outcome"] == "PASS"
    assert (out / "DEMO-0001" / "gimbal-certificate.pdf").stat().st_size > 0
    for axis in ("azimuth", "elevation"):
        unit = out / "DEMO-0001" / axis / "DEMO-0001"
        assert json.loads((unit / "certificate.json").read_text())["outcome"] == "PASS"
        assert (unit / "certificate.pdf").stat().st_size > 0


def test_calibrate_reads_no_conftest_or_pytest_configuration_of_the_current_folder(
    tmp_path: Path,
) -> None:
    operator_folder = tmp_path / "station"
    operator_folder.mkdir()
    (operator_folder / "conftest.py").write_text(HOSTILE_CONFTEST)
    (operator_folder / "pytest.ini").write_text(HOSTILE_CONFIG)
    out = tmp_path / "out"
    result = _calibrate(operator_folder, _without_test_extras(tmp_path), out,
                        "--collect-only", "-q")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "test_inertia_friction" in result.stdout
    assert not (operator_folder / ".pytest_cache").exists()


def test_the_projects_test_run_writes_nowhere_the_user_keeps_results(tmp_path: Path) -> None:
    """A station's store in the environment and the README's ``certificates`` folder in the
    current folder are the user's: the suite's simulated unit goes to a folder of its own."""
    user_store = tmp_path / "line.sqlite"
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    env["GIMBAL_HIL_STORE"] = f"sqlite:///{user_store}"
    command = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q",
               "--rootdir", str(REPOSITORY), "-c", str(REPOSITORY / "pyproject.toml"),
               str(REPOSITORY / "tests" / "test_gum.py"),
               str(REPOSITORY / "protocols" / "test_current_loop.py")]
    result = subprocess.run(command, cwd=tmp_path, env=env, capture_output=True, text=True,
                            timeout=600, check=False)
    assert "passed" in result.stdout, result.stdout[-3000:] + result.stderr[-3000:]
    assert not user_store.exists(), "the test run wrote into the store $GIMBAL_HIL_STORE names"
    assert not (tmp_path / "certificates").exists(), "the test run wrote into ./certificates"
