"""The one order scan: least-squares angle periodogram and matching pursuit, over one
segment or several (each with its own amplitude and phase)."""

from __future__ import annotations

import numpy as np

from hil.identify.orders import (
    FloatArray,
    PursuitLimits,
    Segment,
    matching_pursuit,
    order_range,
    periodogram,
)

LIMITS = PursuitLimits(prominence=20.0, relative_power=0.01, max_orders=8)


def _pass(sign: float, ripple: float, *, seed: int) -> Segment:
    """One constant-velocity pass over 2.4 rad: cogging 84 the same both ways, order 42
    scaled by ``ripple`` (its sign flips with the torque level, as K_t ripple does)."""
    theta = np.linspace(-1.2, 1.2, 20000)[:: int(sign)]
    noise = np.random.default_rng(seed).normal(0.0, 0.0015, theta.size)
    residual = 0.0003 * np.sin(84 * theta + 0.3) + ripple * np.sin(42 * theta + 0.5) + noise
    return Segment(residual=residual, position_rad=theta)


def test_segments_keep_an_order_whose_sign_flips_between_them() -> None:
    up, down = _pass(1.0, 0.0002, seed=0), _pass(-1.0, -0.0002, seed=1)
    found = matching_pursuit([up, down], orders=(10, 200), limits=LIMITS)
    assert sorted(found) == [42, 84]
    # concatenated into one regression the flipped order cancels
    joined = Segment(residual=np.concatenate([up.residual, down.residual]),
                     position_rad=np.concatenate([up.position_rad, down.position_rad]))
    assert matching_pursuit([joined], orders=(10, 200), limits=LIMITS) == [84]


def test_segment_power_is_the_sum_of_each_segment_on_its_own() -> None:
    up, down = _pass(1.0, 0.0002, seed=2), _pass(-1.0, -0.0001, seed=3)
    both = periodogram([up, down], orders=(10, 200))
    one: list[FloatArray] = [periodogram([s], orders=(10, 200)).power for s in (up, down)]
    np.testing.assert_allclose(both.power, one[0] + one[1], rtol=1e-12)
    assert int(both.orders[np.argmax(both.power)]) in (42, 84)


def test_pure_noise_and_empty_ranges_find_nothing() -> None:
    theta = np.linspace(-1.2, 1.2, 20000)
    noise = Segment(residual=np.random.default_rng(4).normal(0.0, 1.0, theta.size),
                    position_rad=theta)
    assert matching_pursuit([noise], orders=(10, 200), limits=LIMITS) == []
    still = np.zeros(100)
    assert order_range(still, None) == (2, 1)
    assert matching_pursuit([Segment(residual=still, position_rad=still)], orders=(2, 1),
                            limits=LIMITS) == []
    assert periodogram([], orders=(10, 200)).orders.size == 0
