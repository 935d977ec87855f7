"""K_t ripple beside a current-loop lag on a 2²⁰-count encoder (docs/diagnose.md, K_t ripple).

The encoder's quantisation, differentiated twice, puts noise as large as the ripple into the
inertia's column on the rows where the ripple is estimated; before the ripple's rows were
band-limited this plant's ripple (order 25, depth 0.136) failed the halves test and went
unnamed. The plant is the seed-7 benchmark's case 13 (``bench_diagnose.py --pairs``).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from diagnose_simdata import plant_with, record

from hil.diagnose.core import diagnose
from hil.diagnose.model import Designer, Model, Term, solve
from hil.diagnose.report import report
from hil.diagnose.signals import prepare


def test_band_limited_design_keeps_a_linear_model_exact() -> None:
    """Effort and columns low-passed alike: the same coefficients, any cutoff."""
    hidden = plant_with(0.004, 0.005, 0.02, (), 40)
    signals = prepare(record(hidden.params, seed=3))
    rng = np.random.default_rng(5)
    columns = rng.standard_normal((len(signals), 2))
    truth = np.array([0.7, -1.3])
    signals = replace(signals, effort_filtered=signals.lowpass(columns @ truth))
    model = Model(terms=(Term(effect="base", labels=("a", "b"), key="random",
                              build=lambda s: columns),))
    rows = signals.rows()
    for cutoff_hz in (signals.cutoff_hz / 5, signals.cutoff_hz / 20):
        matrix, target = Designer().band_limited(model, signals, rows, cutoff_hz)
        fit = solve(model, matrix, target, n_effective=float(rows.size))
        np.testing.assert_allclose(fit.coefficients, truth, rtol=1e-9)


def test_kt_ripple_beside_a_current_lag_is_named_within_15_pct() -> None:
    hidden = plant_with(0.00549, 0.00472, 0.02385,
                        (("kt_ripple", 0.355, 0.519), ("current_lag", 0.765, 0.909)), 51)
    data = report(diagnose(record(hidden.params, seed=44805)))
    causes = {cause["name"]: cause for cause in data["causes"]}
    assert set(causes) == {"kt_ripple", "current_lag"}, list(causes)
    for truth in hidden.truths:
        value = causes[truth.effect]["parameters"][truth.key]
        assert math.isclose(value, truth.truth, rel_tol=0.15), (truth, value)
    assert causes["kt_ripple"]["parameters"]["periods_per_rev"] == 25
