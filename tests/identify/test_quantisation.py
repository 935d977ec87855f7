"""The one quantisation rule: encoder position in slow and fast motion, a torque LSB,
continuous data, and a grid written with rounding noise."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from hil.identify.quantisation import FloatArray, quantisation_step

FS_HZ = 4000.0


def encoder(position_rad: FloatArray, counts_per_rev: int) -> FloatArray:
    """An incremental encoder's reading (floor to a count, zero at 0 rad)."""
    step = 2 * math.pi / counts_per_rev
    return np.floor(position_rad / step) * step


@settings(max_examples=25, deadline=None)
@given(bits=st.integers(10, 20), start=st.floats(-3.0, 3.0),
       counts_per_sample=st.floats(0.01, 0.9))
def test_slow_motion_gives_the_encoder_count(bits: int, start: float,
                                             counts_per_sample: float) -> None:
    """Below one count a sample every level is visited."""
    step = 2 * math.pi / 2**bits
    position = encoder(start + counts_per_sample * step * np.arange(20000), 2**bits)
    assert quantisation_step(position) == pytest.approx(step, rel=1e-9)


@settings(max_examples=25, deadline=None)
@given(bits=st.integers(10, 20), start=st.floats(-3.0, 3.0),
       counts_per_sample=st.floats(1.5, 19.0), sign=st.sampled_from([-1.0, 1.0]))
def test_fast_motion_gives_the_encoder_count_not_the_sample_step(
    bits: int, start: float, counts_per_sample: float, sign: float,
) -> None:
    """One fast pass: every sample moves several counts, the count is their common
    divisor (the smallest change would be several counts, a percentile rule 0).

    A whole number of counts a sample (within 3 %) never shows the finer count: those
    data lie on the coarser grid and are left out."""
    fraction = counts_per_sample % 1.0
    assume(0.03 < fraction < 0.97)
    step = 2 * math.pi / 2**bits
    position = encoder(start + sign * counts_per_sample * step * np.arange(4000), 2**bits)
    assert quantisation_step(position) == pytest.approx(step, rel=1e-9)


@settings(max_examples=25, deadline=None)
@given(lsb_nm=st.floats(1e-5, 1e-2), noise_lsb=st.floats(0.3, 50.0),
       level_nm=st.floats(-0.5, 0.5), seed=st.integers(0, 2**16))
def test_torque_lsb_is_read_off_the_levels(lsb_nm: float, noise_lsb: float, level_nm: float,
                                           seed: int) -> None:
    """A drive's reported torque, quantised after its noise."""
    torque = level_nm + np.random.default_rng(seed).normal(0.0, noise_lsb * lsb_nm, 5000)
    reported = np.round(torque / lsb_nm) * lsb_nm
    assert quantisation_step(reported) == pytest.approx(lsb_nm, rel=1e-6)


@settings(max_examples=25, deadline=None)
@given(scale=st.floats(1e-6, 1e3), size=st.integers(20, 20000), seed=st.integers(0, 2**16))
def test_continuous_data_fits_no_grid(scale: float, size: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    assert quantisation_step(rng.normal(0.0, scale, size)) == 0.0
    assert quantisation_step(np.cumsum(rng.uniform(0.0, scale, size))) == 0.0


@settings(max_examples=25, deadline=None)
@given(bits=st.integers(10, 16), noise_step=st.floats(0.0, 0.02),
       duplicates=st.floats(0.0, 0.03), seed=st.integers(0, 2**16))
def test_a_grid_with_rounding_noise_is_found_and_averaged(
    bits: int, noise_step: float, duplicates: float, seed: int,
) -> None:
    """Levels written with rounding noise (up to 2 % of a step), some of them twice with
    different noise (tiny gaps): the step is still found, averaged over the levels
    rather than taken from the smallest gap."""
    rng = np.random.default_rng(seed)
    step = 2 * math.pi / 2**bits
    counts = np.arange(-3000, 3000)
    counts = np.concatenate([counts, rng.choice(counts, round(duplicates * counts.size))])
    values = (counts + rng.uniform(-noise_step, noise_step, counts.size)) * step
    assert quantisation_step(values) == pytest.approx(step, rel=1e-4)


def test_a_few_glitches_do_not_hide_the_grid() -> None:
    """A few off-grid values (under 5 % of the levels: a spike, a rounding slip)."""
    rng = np.random.default_rng(3)
    values = np.round(rng.normal(0.0, 0.05, 20000) / 0.001) * 0.001
    values[rng.choice(values.size, 5, replace=False)] += rng.uniform(0.0, 0.001, 5)
    assert quantisation_step(values) == pytest.approx(0.001, rel=1e-4)


@pytest.mark.parametrize("values", [np.zeros(0), np.zeros(10), np.array([1.0])])
def test_fewer_than_two_levels_is_not_quantised(values: FloatArray) -> None:
    assert quantisation_step(values) == 0.0
