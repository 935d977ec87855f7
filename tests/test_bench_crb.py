"""The Cramér–Rao machinery of ``benchmarks/bench_crb.py``: bounds that Monte Carlo of an
efficient estimator reaches, and closed forms that agree with the sample-level Jacobian."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks import crb_common, crb_slow

RUNS = 600
# the sample standard deviation over RUNS runs scatters by ≈ 1/√(2·RUNS) ≈ 3 %: 5 σ
TOLERANCE = 5 / math.sqrt(2 * RUNS)


def test_least_squares_reaches_the_linear_bound() -> None:
    """Plain LS on a known design: its Monte Carlo RMSE is σ·sqrt(diag((ΦᵀΦ)⁻¹))."""
    rng = np.random.default_rng(1)
    n, sigma = 400, 0.3
    t = np.linspace(0, 1, n)
    phi = np.column_stack([np.sin(7 * t), t, np.ones(n)])
    theta = np.array([1.0, -2.0, 0.5])
    crb = crb_common.bound(crb_common.linear_information(phi, sigma), np.eye(3))
    errors = np.array(
        [
            np.linalg.lstsq(phi, phi @ theta + sigma * rng.standard_normal(n), rcond=None)[0]
            - theta
            for _ in range(RUNS)
        ]
    )
    ratio = np.sqrt(np.mean(errors**2, axis=0)) / crb
    assert np.all(np.abs(ratio - 1) < TOLERANCE), ratio


def test_bound_of_a_function_is_the_delta_method() -> None:
    information = np.array([[4.0, 1.0], [1.0, 2.0]])
    grad = np.array([0.6, 0.8])
    expected = math.sqrt(grad @ np.linalg.inv(information) @ grad)
    assert crb_common.bound(information, grad)[0] == pytest.approx(expected)


def _sine_blocks(
    inertia: float, *, sigma: float, rng: np.random.Generator | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[tuple[int, int]]]:
    fs, f, blocks = 1000.0, 20.0, 4
    time_s = np.arange(400) / fs  # 8 periods, 2 per block
    position = 0.01 * np.sin(2 * math.pi * f * time_s + 0.3)
    torque = -inertia * (2 * math.pi * f) ** 2 * position
    if rng is not None:
        torque = torque + sigma * rng.standard_normal(time_s.size)
    edges = [(100 * k, 100 * (k + 1)) for k in range(blocks)]
    return time_s, position, torque, edges


def test_frf_bound_equals_the_sample_level_bound_and_is_reached() -> None:
    """A double integrator ``H = −1/(J·ω²)``: the bound through the block phasors equals the
    sample-level bound with the blocks' trend columns free, and LS on the samples (an
    efficient estimator of J) reaches it."""
    inertia, sigma, f, fs = 0.004, 0.002, 20.0, 1000.0
    omega = 2 * math.pi * f
    time_s, position, _, edges = _sine_blocks(inertia, sigma=sigma, rng=None)
    point = crb_common.frf_blocks(
        time_s, position, frequency_hz=f, fs_hz=fs, blocks=len(edges), sigma=sigma
    )

    def response(x: np.ndarray) -> np.ndarray:
        return np.array([-1.0 / (x[0] * omega**2)], dtype=np.complex128)

    info = crb_common.frf_information([point], response, np.array([inertia]), np.array([1e-7]))
    frf_crb = crb_common.bound(info, np.ones(1))[0]

    columns = [-(omega**2) * position]
    for a, b in edges:
        for power in (0, 1):
            column = np.zeros(time_s.size)
            column[a:b] = (time_s[a:b] - time_s[a:b].mean()) ** power
            columns.append(column)
    phi = np.column_stack(columns)
    sample_crb = crb_common.bound(crb_common.linear_information(phi, sigma), np.eye(9)[0])[0]
    assert frf_crb == pytest.approx(sample_crb, rel=1e-3)

    rng = np.random.default_rng(2)
    estimates = []
    for _ in range(RUNS):
        torque = _sine_blocks(inertia, sigma=sigma, rng=rng)[2]
        estimates.append(np.linalg.lstsq(phi, torque, rcond=None)[0][0])
    rmse = math.sqrt(float(np.mean((np.array(estimates) - inertia) ** 2)))
    assert abs(rmse / frf_crb - 1) < TOLERANCE


def test_stribeck_closed_form_matches_the_sample_jacobian() -> None:
    """Eliminating the per-block loads in closed form gives the bound of the full
    sample-level Jacobian (friction ± per direction, one free load per block)."""
    truth = (0.02, 0.026, 0.02, 0.005)
    tc, ts, vs, _ = truth
    speeds = np.array([0.4, 0.1, 0.04, 0.02, 0.01, 0.005])
    sigma = 0.0015
    counts = [[(50 + 7 * k, 60 - 3 * k) for k in range(3)] for _ in speeds]
    rows, load_columns = [], 0
    for v, blocks in zip(speeds, counts, strict=True):
        e = math.exp(-((v / vs) ** 2))
        grad = np.array([1 - e, e, (ts - tc) * e * 2 * v**2 / vs**3, v])
        for n_plus, n_minus in blocks:
            for sign, n in ((1.0, n_plus), (-1.0, n_minus)):
                rows.append((np.tile(sign * grad, (n, 1)), load_columns, n))
            load_columns += 1
    jac = np.zeros((sum(r[2] for r in rows), 4 + load_columns))
    start = 0
    for block, column, n in rows:
        jac[start : start + n, :4] = block
        jac[start : start + n, 4 + column] = 1.0
        start += n
    brute = crb_common.bound(
        crb_common.linear_information(jac, sigma), np.eye(4 + load_columns)[:4]
    )
    information = np.array(
        [sum(4 / (sigma**2 * (1 / p + 1 / m)) for p, m in blocks) for blocks in counts]
    )
    closed = crb_slow.stribeck_crb(speeds, information, truth)
    np.testing.assert_allclose(closed, brute, rtol=1e-9)
