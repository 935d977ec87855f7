"""Diagnosis of recordings that no single simulator shapes (issue 29).

Recordings of ``plant_sim.variant``, whose choices (integrator and sub-steps, static or
LuGre friction, velocity estimator, PI structure and torque filter, sample rate and jitter,
encoder resolution, noise colour, torque before or after the current loop) are not the
main simulator's. The rates over drawn variants are the benchmark's
(``benchmarks/bench_diagnose.py --variants``, docs/diagnose.md "Recordings no single
simulator shapes"): no effect is recovered on every variant yet, so no test draws them
here; these pin what was traced and mended on one of them.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from diagnose_simdata import Truth, observable, plant, record
from test_diagnose_hidden import recovered

from hil.diagnose.core import diagnose
from hil.diagnose.report import report
from plant_sim.variant import MAIN_LIKE, TorqueTap, draw_variant

pytestmark = pytest.mark.slow(seconds=60)

DRAWN = draw_variant(np.random.default_rng(0))
"""An rk4 integrator, 2 kHz with 1.7 % period jitter, a 2^17-count encoder, the torque
acting half a period late, a moving-average estimator, a 2-DOF PI with a torque filter and
low-passed torque noise (the first variant Hypothesis drew)."""


@pytest.mark.parametrize("effect", ["offset", "two_mass"])
def test_a_jittered_coarse_recording_names_no_lag_that_is_not_there(effect: str) -> None:
    """On that variant the lag search had no quantisation stand-ins (it looked for the
    encoder's step on the resampled position, which lies between the levels) and named a
    0.8 ms lag beside a resonance and a 50 ms one, the top of its range, beside an offset."""
    hidden = plant(0.002, 0.003, 0.015, effect, 0.0, 0.0, 60)
    data = report(diagnose(record(hidden.params, seed=0, variant=DRAWN)))
    assert [cause["name"] for cause in data["causes"]] == [effect]
    assert hidden.key is not None
    assert recovered(data["causes"][0], hidden.key, hidden.truth)


def test_a_lag_before_a_measured_torque_is_not_in_the_data() -> None:
    """A torque reported after the current loop (the measured current) is the torque the
    motor makes: the loop's lag is not in that recording (the benchmark does not count it
    as hidden there, ``observable``), and none is named."""
    hidden = plant(0.004, 0.005, 0.02, "current_lag", 0.5, 0.5, 60)
    taps: tuple[tuple[TorqueTap, list[str]], ...] = (("command", ["current_lag"]),
                                                      ("measured", []))
    for tap, named in taps:
        variant = dataclasses.replace(MAIN_LIKE, torque_tap=tap)
        data = report(diagnose(record(hidden.params, seed=3, variant=variant)))
        assert [cause["name"] for cause in data["causes"]] == named, tap
        truths = observable((Truth(effect="current_lag", key="time_constant_s",
                                   truth=hidden.truth),), variant)
        assert len(truths) == len(named)
