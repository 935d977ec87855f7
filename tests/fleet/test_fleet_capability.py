"""Capability indices and their intervals against Montgomery's worked examples, and the
within-σ interval's coverage measured by Monte Carlo.

Montgomery, D. C., *Introduction to Statistical Quality Control*, 6th ed., Wiley 2009,
ch. 8, the worked examples of confidence intervals on process capability ratios:
- Cp: USL = 62, LSL = 38, n = 20, s = 1.75 → Ĉp = 2.29, 95 % CI 1.57 ≤ Cp ≤ 3.01
  (χ²₀.₀₂₅,₁₉ = 8.91, χ²₀.₉₇₅,₁₉ = 32.85).
- Cpk: n = 20, Ĉpk = 1.33 → 95 % CI 0.88 ≤ Cpk ≤ 1.78 (Bissell's approximation).
NIST/SEMATECH e-Handbook of Statistical Methods, §6.1.6 (What is process capability?):
USL = 20, LSL = 8, μ = 16, σ = 2 → Cp = 1, Cpk = 0.6667.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.errors import InputError
from hil.fleet.capability import (
    D2,
    capability,
    cp_interval,
    cpk_interval,
    mr_sigma_dof,
    sigma_within,
)


def test_montgomery_cp_interval_example() -> None:
    cp = (62 - 38) / (6 * 1.75)
    assert round(cp, 2) == 2.29
    low, high = cp_interval(2.29, 19, 0.95)  # the book carries the rounded Ĉp on
    assert (round(low, 2), round(high, 2)) == (1.57, 3.01)


def test_montgomery_cpk_interval_example() -> None:
    low, high = cpk_interval(1.33, 20, 19, 0.95)
    assert (round(low, 2), round(high, 2)) == (0.88, 1.78)


def _exact_moments(mean: float, sd: float, n: int) -> np.ndarray:
    """n values with exactly this mean and sample standard deviation."""
    z = np.random.default_rng(3).standard_normal(n)
    z = (z - z.mean()) / z.std(ddof=1)
    return mean + sd * z


def test_nist_6_1_6_indices_with_the_overall_sigma() -> None:
    c = capability(_exact_moments(16.0, 2.0, 40), lower_limit=8.0, upper_limit=20.0)
    assert c.pp.value == pytest.approx(1.0, abs=1e-12)
    assert c.ppk.value == pytest.approx(0.6667, abs=5e-5)
    assert c.pp.n == c.ppk.n == 40


def test_within_sigma_is_the_average_moving_range_over_d2() -> None:
    x = np.array([10.0, 12.0, 11.0, 15.0, 14.0])
    assert sigma_within(x) == pytest.approx((2 + 1 + 4 + 1) / 4 / 1.128)
    c = capability(x, lower_limit=0.0, upper_limit=30.0)
    s_w = 2.0 / D2
    assert c.cp.value == pytest.approx(30 / (6 * s_w))
    assert c.cpk.value == pytest.approx(min(30 - 12.4, 12.4) / (3 * s_w))
    assert c.pp.value == pytest.approx(30 / (6 * float(np.std(x, ddof=1))))


def test_one_sided_limit_gives_the_one_sided_index_and_no_cp() -> None:
    x = _exact_moments(5.0, 1.0, 30)
    c = capability(x, lower_limit=None, upper_limit=11.0)
    assert c.cp.value is None
    assert c.pp.value is None
    assert c.ppk.value == pytest.approx(2.0)
    assert c.cpk.value == pytest.approx(6.0 / (3 * sigma_within(x)))


def test_effective_dof_of_the_moving_range_sigma() -> None:
    # exact to first order; tends to 0.605 (n − 1) (docs/fleet.md §1)
    assert mr_sigma_dof(2) == pytest.approx((4 / math.pi) / (2 * (2 - 4 / math.pi)))
    assert mr_sigma_dof(100_001) / 100_000 == pytest.approx(0.6050, abs=2e-4)


def test_within_sigma_interval_covers_at_its_level() -> None:
    """2000 seeded samples of n = 50 from N(0, 1), limits −4 / +4.5 (Cp = 1.417,
    Cpk = 1.333): every interval's coverage within 0.025 of 95 % (4 binomial SE = 0.0195,
    plus 0.005 for the approximations). With ν = n − 1 instead of the moving range's
    effective ν, the within-σ Cp interval would be too narrow and cover < 90 %."""
    rng = np.random.default_rng(20261124)
    samples = rng.standard_normal((2000, 50))
    true_cp, true_cpk = 8.5 / 6, 4.0 / 3
    hits = {"cp": 0, "cpk": 0, "pp": 0, "ppk": 0}
    naive = 0
    for x in samples:
        c = capability(x, lower_limit=-4.0, upper_limit=4.5)
        for name, truth in (("cp", true_cp), ("pp", true_cp), ("cpk", true_cpk),
                            ("ppk", true_cpk)):
            est = getattr(c, name)
            hits[name] += est.low <= truth <= est.high
        low, high = cp_interval(c.cp.value, 49, 0.95)
        naive += low <= true_cp <= high
    for name, count in hits.items():
        assert abs(count / 2000 - 0.95) <= 0.025, (name, count / 2000)
    assert naive / 2000 < 0.90


@pytest.mark.parametrize(
    ("values", "lower", "upper", "message"),
    [([1.0], 0.0, 2.0, "at least 2 values"),
     ([1.0, 2.0], None, None, "lower or an upper"),
     ([1.0, 2.0], 3.0, 2.0, "not above"),
     ([1.0, 1.0, 1.0], 0.0, 2.0, "do not vary"),
     ([1.0, float("nan")], 0.0, 2.0, "not finite")],
)
def test_bad_input_is_one_clear_error(values: list[float], lower: float | None,
                                      upper: float | None, message: str) -> None:
    with pytest.raises(InputError, match=message):
        capability(values, lower_limit=lower, upper_limit=upper)
