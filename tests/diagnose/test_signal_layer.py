"""The signal layer diagnosis shares with identification (hil.identify.kinematics)."""

from __future__ import annotations

import numpy as np

from hil.diagnose.signals import derivatives
from hil.identify.kinematics import phase_free_derivatives


def test_diagnosis_derivatives_are_exact_on_a_quartic_to_the_segment_ends() -> None:
    step_s = 1e-3
    t = np.arange(400) * step_s
    x = 3.0 * t**4 - 2.0 * t**3 + t**2 - 5.0 * t + 1.0
    first, second = derivatives(x, step_s=step_s, segments=((0, 150), (160, 400)))
    inside = np.r_[0:150, 160:400]
    np.testing.assert_allclose(first[inside], (12 * t**3 - 6 * t**2 + 2 * t - 5)[inside],
                               rtol=0, atol=1e-9)
    np.testing.assert_allclose(second[inside], (36 * t**2 - 12 * t + 2)[inside],
                               rtol=0, atol=1e-6)
    assert not first[150:160].any()
    assert not second[150:160].any()


def test_identification_and_diagnosis_agree_on_a_slow_sine() -> None:
    """Both settings of the one differentiator give the same motion of a well-sampled sine."""
    step_s = 5e-4
    t = np.arange(4000) * step_s
    x = 0.3 * np.sin(2 * np.pi * 2.0 * t)
    wide = phase_free_derivatives(x, time_s=t, window_s=0.01)
    narrow = derivatives(x, step_s=step_s, segments=((0, len(t)),))
    for a, b in zip(wide, narrow, strict=True):
        np.testing.assert_allclose(a[10:-10], b[10:-10], rtol=0, atol=1e-6 * np.max(np.abs(b)))
