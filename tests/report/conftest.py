"""Calibration runs the certificate-document tests share, each run once per session."""

from __future__ import annotations

import pytest

from hil.profile import builtin_profile_path
from tests.report.runs import Run, calibrate


@pytest.fixture(scope="session")
def elevation_run(tmp_path_factory: pytest.TempPathFactory) -> Run:
    """The elevation demo unit, every protocol its profile configures (six)."""
    run = calibrate(tmp_path_factory.mktemp("elevation"), "RPT-0001")
    assert run.returncode == 0, run.stdout
    return run


@pytest.fixture(scope="session")
def failed_run(tmp_path_factory: pytest.TempPathFactory) -> Run:
    """The J/B/T_c protocol against a profile expecting a J the demo unit does not have."""
    out = tmp_path_factory.mktemp("failed")
    text = builtin_profile_path().read_text(encoding="utf-8")
    old, new = "nominal = 0.0036\ntolerance_pct = 15", "nominal = 0.0050\ntolerance_pct = 10"
    assert old in text
    profile = out / "unit.toml"
    profile.write_text(text.replace(old, new), encoding="utf-8")
    run = calibrate(out, "RPT-FAIL", "--profile", str(profile), "--", "-k", "inertia_friction")
    assert run.returncode == 1, run.stdout
    return run
