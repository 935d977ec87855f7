"""The 95 % intervals of named causes hold the truth about as often as they claim.

Eight simulated recordings, each with one hidden effect whose key parameter is linear
(type, size, plant and noise drawn from a fixed seed; the diagnoser never sees them).
Every named cause's key parameter carries a standard uncertainty ``u`` and a 95 %
interval. Over the eight, the interval must hold the truth at least seven times, and the
normalised errors ``(value − truth)/u`` must have an RMS between 0.35 and 2: intervals
three times too narrow, or three times too wide, fail. The benchmark measures the
coverage over many more recordings (docs/diagnose.md).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from diagnose_simdata import plant, record

from hil.diagnose.core import diagnose
from hil.diagnose.report import report

LINEAR = ("offset", "asymmetric_friction", "gravity", "cable_spring", "cogging")
SEED = 20261124


@pytest.mark.xfail(strict=True, reason=(
    "issue 12, not mended: the 95 % intervals hold the truth in 68 % of single hidden "
    "effects (25/37, benchmark), errors/u RMS 2.5: the Newey-West u covers the noise, not "
    "the model's remaining bias (gravity +1 %, a cable spring named as gravity)"))
def test_intervals_cover_the_truth() -> None:
    rng = np.random.default_rng(SEED)
    covered = 0
    errors = []
    for case in range(8):
        effect = LINEAR[case % len(LINEAR)]
        hidden = plant(float(rng.uniform(0.002, 0.006)), float(rng.uniform(0.003, 0.008)),
                       float(rng.uniform(0.015, 0.03)), effect, float(rng.uniform()),
                       float(rng.uniform()), int(rng.integers(24, 121)))
        data = report(diagnose(record(hidden.params, seed=int(rng.integers(0, 2**16)))))
        cause = next((c for c in data["causes"] if c["name"] == effect), None)
        assert hidden.key is not None
        if cause is None:  # not named: no interval holds the truth
            errors.append(float("inf"))
            continue
        entry = cause["uncertainty"][hidden.key]
        low, high = entry["ci95"]
        covered += low <= hidden.truth <= high
        errors.append((entry["value"] - hidden.truth) / entry["std"])
    z_rms = math.sqrt(sum(z * z for z in errors) / len(errors))
    assert covered >= 7, (covered, errors)
    assert 0.35 <= z_rms <= 2.0, errors
