"""Hypothesis profiles for the project's tests: ``ci`` (default: deterministic, no deadline)
and ``dev`` (fewer examples), chosen with ``HYPOTHESIS_PROFILE``; draws that do not
depend on which of the project's modules a run has imported; and a test run that writes
nowhere a user keeps results."""

from __future__ import annotations

import os
import tempfile

import pytest
from hypothesis import HealthCheck, settings
from hypothesis.internal.conjecture import providers
from hypothesis.internal.constants_ast import Constants
from numba.core.registry import cpu_target

settings.register_profile(
    "ci",
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
settings.register_profile("dev", deadline=None, max_examples=10)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

# Hypothesis mixes numbers found in the local modules loaded so far (hil/, plant_sim/, ...)
# into its draws (hypothesis.internal.conjecture.providers), a pool that grows with every
# module imported: a test file run alone and the same file in the whole suite drew
# different units, and a number edited anywhere in the project could move every test's
# draws. Off: derandomized draws depend on the test's own source and the pinned release.
_NO_LOCAL_CONSTANTS = Constants()
providers._get_local_constants = lambda: _NO_LOCAL_CONSTANTS


# pytester restores sys.modules after each in-process run, so a module first imported
# inside one is imported afresh later. numba refuses that of the typing registries its
# CPU target loads on first use ("duplicate registration for PolynomialType": every
# diagnosis test after tests/test_rate.py failed, in whichever run put them after it).
# They are loaded here, before any run.
cpu_target.target_context.refresh()


# The project's own tests decide where they write from nothing of the user's: not the
# results store or operator their environment names (a station's line database), not the
# ``certificates`` folder the README's first command fills. The suite's simulated unit
# goes to a folder of its own, with its own SQLite store, unless --out names one.
for _name in ("GIMBAL_HIL_STORE", "GIMBAL_HIL_OPERATOR"):
    os.environ.pop(_name, None)


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config: pytest.Config) -> None:
    if config.getoption("--out", default=None) == "certificates":  # the option's default
        config.option.out = tempfile.mkdtemp(prefix="gimbal-hil-tests-")
