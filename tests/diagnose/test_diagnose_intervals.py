"""The 95 % intervals of named causes hold the truth about as often as they claim.

Eight simulated recordings, each with one hidden effect whose key parameter is linear
(type, size, plant and noise drawn from a fixed seed; the diagnoser never sees them).
Every named cause's key parameter carries a standard uncertainty ``u`` (delete-a-group
jackknife, 15 degrees of freedom) and a 95 % interval. The tolerances are those a method
that is right would pass with 99 % probability:

- coverage: the interval holds the truth in at least ``k`` of the eight, ``k`` the
  binomial's 1 % point for a true 95 % (6 of 8); an effect not named counts as a miss;
- width: the normalised errors ``(value − truth)/u`` of the named causes have an RMS
  inside the χ² 99 % band for their number, the upper end widened by the jackknife's
  Student-t variance ratio 15/13 (too narrow), the lower end not (too wide).

The benchmark measures the coverage over many more recordings (docs/diagnose.md).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from diagnose_simdata import plant, record
from scipy import stats

from hil.diagnose.core import diagnose
from hil.diagnose.intervals import JACKKNIFE_GROUPS
from hil.diagnose.report import report

pytestmark = pytest.mark.slow(seconds=30)

LINEAR = ("offset", "asymmetric_friction", "gravity", "cable_spring", "cogging")
SEED = 20261124
CASES = 8
#: Probability with which a right method may fail either check.
RISK = 0.01


def _least_covered(cases: int) -> int:
    """The smallest count a method with 95 % coverage reaches with probability ≥ 1 − RISK."""
    return int(stats.binom.ppf(RISK, cases, 0.95))


def _rms_band(count: int) -> tuple[float, float]:
    """RMS of ``count`` normalised errors: the χ² band at ``RISK`` (t-widened upper end)."""
    dof = JACKKNIFE_GROUPS - 1
    low, high = stats.chi2.ppf([RISK / 2, 1 - RISK / 2], count) / count
    return math.sqrt(low), math.sqrt(high * dof / (dof - 2))


def test_tolerances_follow_from_the_binomial_and_chi2() -> None:
    assert _least_covered(CASES) == 6
    assert stats.binom.cdf(_least_covered(CASES) - 1, CASES, 0.95) <= RISK
    low, high = _rms_band(7)
    assert 0.37 < low < 0.38
    assert 1.82 < high < 1.84


def test_intervals_cover_the_truth() -> None:
    rng = np.random.default_rng(SEED)
    covered = 0
    errors = []
    for case in range(CASES):
        effect = LINEAR[case % len(LINEAR)]
        hidden = plant(float(rng.uniform(0.002, 0.006)), float(rng.uniform(0.003, 0.008)),
                       float(rng.uniform(0.015, 0.03)), effect, float(rng.uniform()),
                       float(rng.uniform()), int(rng.integers(24, 121)))
        data = report(diagnose(record(hidden.params, seed=int(rng.integers(0, 2**16)))))
        cause = next((c for c in data["causes"] if c["name"] == effect), None)
        assert hidden.key is not None
        if cause is None:  # not named: no interval holds the truth
            continue
        entry = cause["uncertainty"][hidden.key]
        low, high = entry["ci95"]
        covered += low <= hidden.truth <= high
        errors.append((entry["value"] - hidden.truth) / entry["std"])
    z_rms = math.sqrt(sum(z * z for z in errors) / len(errors))
    assert covered >= _least_covered(CASES), (covered, errors)
    low, high = _rms_band(len(errors))
    assert low <= z_rms <= high, (z_rms, errors)
