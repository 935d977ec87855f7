"""I-MR limits and the EWMA chart against published worked examples.

- NIST/SEMATECH e-Handbook of Statistical Methods, §6.3.2.2 (individuals control charts),
  flow-rate example, 10 batches: moving ranges 2.0 2.3 1.4 3.5 3.4 1.4 0.2 1.2 1.5,
  x̄ = 50.81, MR̄ = 1.8778, UCL = 55.8041, LCL = 45.8159; "the process is in control".
- NIST/SEMATECH e-Handbook §6.3.2.4 (EWMA control charts): 20 values, EWMA₀ = 50,
  s = 2.0539, λ = 0.3, k = 3; the EWMA series printed to two decimals; asymptotic limits
  UCL = 52.5884, LCL = 47.4115 computed with the factor √(λ/(2−λ)) rounded to 0.4201;
  no point beyond them.
- Montgomery, *Introduction to SQC*, 6th ed., Table 9.1 data with μ₀ = 10, σ = 1, and the
  EWMA of ch. 9 with λ = 0.1, L = 2.7 (data as reproduced in the IMSL C#/.NET manual's EWMA
  example, which cites "Montgomery 428"); the z and the exact limits are recomputed here in
  closed form, independently of the recursion under test.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.errors import InputError
from hil.fleet.capability import moving_ranges
from hil.fleet.charts import EwmaSettings, ewma_chart, imr_limits
from hil.fleet.rules import nelson_rules

FLOWRATE = [49.6, 47.6, 49.9, 51.3, 47.8, 51.2, 52.6, 52.4, 53.6, 52.1]
NIST_EWMA_DATA = [52.0, 47.0, 53.0, 49.3, 50.1, 47.0, 51.0, 50.1, 51.2, 50.5,
                  49.6, 47.6, 49.9, 51.3, 47.8, 51.2, 52.6, 52.4, 53.6, 52.1]
NIST_EWMA_PRINTED = [50.60, 49.52, 50.56, 50.18, 50.16, 49.21, 49.75, 49.85, 50.26, 50.33,
                     50.11, 49.36, 49.52, 50.05, 49.38, 49.92, 50.73, 51.23, 51.94, 51.99]
MONTGOMERY_9_1 = [9.45, 7.99, 9.29, 11.66, 12.16, 10.18, 8.04, 11.46, 9.20, 10.34,
                  9.03, 11.47, 10.51, 9.40, 10.08, 9.37, 10.62, 10.31, 8.52, 10.84,
                  10.90, 9.33, 12.29, 11.50, 10.60, 11.08, 10.38, 11.62, 11.31, 10.52]


def test_nist_individuals_chart_flowrate() -> None:
    lim = imr_limits(FLOWRATE)
    assert np.round(moving_ranges(FLOWRATE), 1).tolist() == \
        [2.0, 2.3, 1.4, 3.5, 3.4, 1.4, 0.2, 1.2, 1.5]
    assert round(lim.centre, 2) == 50.81
    assert round(lim.mr_centre, 4) == 1.8778
    assert round(lim.ucl, 4) == 55.8041
    assert round(lim.lcl, 4) == 45.8159
    assert lim.mr_ucl == pytest.approx(3.267 * 1.8778, abs=1e-4)  # D4 for span 2
    # "in control": no rule fires, not even the supplementary ones
    hits = nelson_rules(FLOWRATE, centre=lim.centre, sigma=lim.sigma, rules="all")
    assert all(not h for h in hits.values())


def test_nist_ewma_example() -> None:
    e = ewma_chart(NIST_EWMA_DATA, centre=50.0, sigma=2.0539,
                   settings=EwmaSettings(lam=0.3, width=3.0))
    assert np.round(e.z, 2).tolist() == NIST_EWMA_PRINTED
    assert e.signals == []
    # exact limits: widening towards 50 ± 3 s √(λ/(2−λ)) (NIST rounds the factor to 0.4201,
    # which moves its printed limits by 3 · 2.0539 · 1.6e-5 = 1.0e-4)
    assert e.ucl[0] == pytest.approx(50 + 3 * 2.0539 * 0.3, rel=1e-12)  # i = 1: factor λ
    assert np.all(np.diff(e.ucl) > 0)
    assert e.ucl[-1] == pytest.approx(52.5884, abs=1.5e-4)
    assert e.lcl[-1] == pytest.approx(47.4115, abs=1.5e-4)


def test_montgomery_table_9_1_ewma_in_closed_form() -> None:
    lam, width, mu0, sigma = 0.1, 2.7, 10.0, 1.0
    e = ewma_chart(MONTGOMERY_9_1, centre=mu0, sigma=sigma,
                   settings=EwmaSettings(lam=lam, width=width))
    x = np.array(MONTGOMERY_9_1)
    for i in range(1, x.size + 1):
        weights = lam * (1 - lam) ** np.arange(i - 1, -1, -1)
        z_i = float(weights @ x[:i]) + (1 - lam) ** i * mu0
        half = width * sigma * np.sqrt(lam / (2 - lam) * (1 - (1 - lam) ** (2 * i)))
        assert e.z[i - 1] == pytest.approx(z_i, abs=1e-12)
        assert e.ucl[i - 1] == pytest.approx(mu0 + half, abs=1e-12)
    # z₂₈ = 10.5731 < 10.6186; z₂₉ = 10.6468 and z₃₀ = 10.6341 beyond 10.6187 / 10.6189
    assert e.signals == [28, 29]
    # the Shewhart chart of the same data (3σ about 10) has no point outside (Montgomery
    # Fig. 9.1, the reason the chapter turns to CUSUM and EWMA)
    assert nelson_rules(x, centre=mu0, sigma=sigma, rules=[1]) == {1: []}


@given(values=st.lists(st.floats(-1e3, 1e3), min_size=1, max_size=40),
       width=st.floats(0.5, 4.0))
def test_ewma_with_lambda_one_is_the_shewhart_chart(values: list[float], width: float) -> None:
    e = ewma_chart(values, centre=0.0, sigma=2.0, settings=EwmaSettings(lam=1.0, width=width))
    assert e.z.tolist() == values
    assert np.allclose(e.ucl, 2.0 * width)
    assert np.allclose(e.lcl, -2.0 * width)


@settings(max_examples=40)
@given(seed=st.integers(0, 2**32 - 1))
def test_ewma_catches_a_two_sigma_shift(seed: int) -> None:
    """λ = 0.2, L = 3, known μ₀ and σ, 25 in-control runs then 25 shifted by 2σ: in 2000
    seeded trials of this set-up (numpy seed 1) every shift was caught within 20 shifted
    runs, so a miss within 25 is far rarer than 1 in 2000."""
    rng = np.random.default_rng(seed)
    x = np.concatenate([rng.standard_normal(25), 2.0 + rng.standard_normal(25)])
    e = ewma_chart(x, centre=0.0, sigma=1.0, settings=EwmaSettings())
    assert any(i >= 25 for i in e.signals)


@pytest.mark.parametrize(("lam", "width"), [(0.0, 3.0), (1.5, 3.0), (0.2, 0.0)])
def test_bad_ewma_settings(lam: float, width: float) -> None:
    with pytest.raises(InputError, match="EWMA"):
        EwmaSettings(lam=lam, width=width)


def test_too_few_points_for_a_chart() -> None:
    with pytest.raises(InputError, match="at least 2"):
        imr_limits([1.0])
