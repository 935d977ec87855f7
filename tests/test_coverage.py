"""The stated uncertainties describe the errors: a small population of simulated units,
calibrated as a user would, against the truth each result claims (the benchmark
``gimbal-hil characterise`` at 30 units; its truth map is in :mod:`hil.characterise.truth`).

A result fails when its k = 2 interval covers the truth in fewer than 80 % of the units or
the RMS of ``(x − truth)/u`` leaves 0.5–2.0 (both a 95 %-coverage uncertainty would meet
with n = 30 except with a probability below 0.2 %). Results with no truth of the plant's
are judged by repeatability: the same unit under two noise seeds,
``(x₁ − x₂)/√(u₁² + u₂²)``, whose RMS over n pairs must lie in the central 99.8 % of
``√(χ²ₙ/n)`` (n = 8: 0.33–1.81; n = 16: 0.50–1.57; a range folded at zero, the J
amplitude spread, from 0.28 at n = 16). The population is drawn with its
own seed, not the one the shipped method-bias map was measured on.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from hil.characterise.draw import write_population
from hil.characterise.run import Row, calibrate, run_population
from hil.characterise.summary import Summary, repeatability, summarise
from hil.characterise.truth import NO_TRUTH

UNITS_PER_PROFILE = 15
PAIRS_PER_PROFILE = 8
POPULATION_SEED = 7  # the shipped map was measured on seed 11, the benchmark table on 2026
MIN_COVERAGE = 0.80
RMS_RANGE = (0.5, 2.0)

# two at a time alone; one under pytest-xdist, whose other workers have the other cores
CALIBRATIONS_AT_ONCE = 1 if os.environ.get("PYTEST_XDIST_WORKER") else 2

pytestmark = pytest.mark.slow(seconds=240)


Population = tuple[list[Row], dict[str, list[float]]]


@pytest.fixture(scope="module")
def population(tmp_path_factory: pytest.TempPathFactory) -> Population:
    directory = tmp_path_factory.mktemp("coverage")
    units = write_population(directory / "units", units_per_profile=UNITS_PER_PROFILE,
                             seed=POPULATION_SEED)
    rows = run_population(units, directory / "certificates", workers=CALIBRATIONS_AT_ONCE)
    twice = [u for u in units if int(u.serial.split("-")[1]) < PAIRS_PER_PROFILE]
    with ThreadPoolExecutor(max_workers=CALIBRATIONS_AT_ONCE) as pool:  # the second runs
        seconds = list(pool.map(
            lambda unit: calibrate(unit, directory / "pairs", seed=unit.seed + 1), twice))
    paired: dict[str, list[float]] = {}
    for unit, second in zip(twice, seconds, strict=True):
        first = calibrate(unit, directory / "certificates", reuse=True)  # the population's
        for name, z in repeatability(first, second).items():
            paired.setdefault(name, []).append(z)
    return rows, paired


def pooled(rows: list[Row]) -> dict[str, Summary]:
    """Coverage and RMS normalised error per result, both profiles together."""
    return {s.parameter: s for s in summarise([replace(r, axis="both") for r in rows])}


def test_every_unit_was_calibrated(
    population: Population,
) -> None:
    rows, _ = population
    assert len({r.unit for r in rows}) == 2 * UNITS_PER_PROFILE


def test_intervals_cover_the_truth(population: Population) -> None:
    rows, _ = population
    summaries = pooled(rows)
    assert len(summaries) >= 20
    misses = {
        name: f"coverage {s.coverage:.0%}, RMS (x−truth)/u {s.rms_normalised:.2f}, n {s.n}"
        for name, s in summaries.items()
        if s.coverage < MIN_COVERAGE or not RMS_RANGE[0] <= s.rms_normalised <= RMS_RANGE[1]
    }
    assert not misses, misses


# a range (largest minus smallest J over their mean) is folded at zero: where a unit's true
# spread is nil two runs differ by |e₁| − |e₂|, with (1 − 2/π) of the variance of e₁ − e₂
# (RMS 0.60 under a right u). Its lower bound is that fold's 0.1 % point, the most lenient
# any true spread allows; the upper stays the Gaussian one (a spread far from zero).
FOLDED = {"inertia_amplitude_spread_pct"}


def _folded_low(n: int, draws: int = 100_000) -> float:
    """The 0.1 % point of the RMS of ``n`` values ``(|a| − |b|)/√2``, a and b standard normal."""
    a, b = np.random.default_rng(0).standard_normal((2, draws, n))
    rms = np.sqrt(np.mean(((np.abs(a) - np.abs(b)) / math.sqrt(2)) ** 2, axis=1))
    return float(np.quantile(rms, 0.001))


def test_results_without_a_truth_repeat_within_their_uncertainty(
    population: Population,
) -> None:
    _, paired = population
    for name in NO_TRUTH:
        assert name in paired, f"{name}: never calibrated twice"
        n = len(paired[name])
        low, high = (math.sqrt(stats.chi2.ppf(p, n) / n) for p in (0.001, 0.999))
        if name in FOLDED:
            low = _folded_low(n)
        rms = float(np.sqrt(np.mean(np.square(paired[name]))))
        assert low <= rms <= high, f"{name}: RMS {rms:.2f} outside [{low:.2f}, {high:.2f}]"
