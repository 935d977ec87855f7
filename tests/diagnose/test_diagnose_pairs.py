"""Hypothesis hides two effects at once (pair, sizes and shapes drawn): both recovered, nothing
else named.

The diagnoser never sees which effects, their sizes or the truth; draws are derandomized
(see ``test_diagnose_hidden.py``). A hidden effect is recovered when it is named with its
key parameter within 15 % (or, flagged ``separable: false``, its 95 % interval holds the
truth), or when a named cause declares itself not separable from it and the declared
interval of its key parameter holds the truth (docs/diagnose.md, "Effects the recording
cannot separate"); a named cause that is not hidden fails the test unless it declares
itself not separable from a hidden one.

Excluded: the pairs with a current-loop lag. The lag comes out 10-30 % low beside another
effect as alone (docs/diagnose.md, Limits; another change mends it): with the lag
``benchmarks/bench_diagnose.py --pairs --hidden 105 --seed 7`` recovers both effects in
PAIRS_WITH_LAG_RATE of the lag's 30 cases. The other 15 pairs are drawn.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

from diagnose_simdata import Truth, plant_with, record
from hypothesis import given, settings
from hypothesis import strategies as st
from test_diagnose_hidden import DETERMINISTIC, recovered

from hil.diagnose.core import diagnose
from hil.diagnose.report import report

SEVEN = ("stribeck", "cogging", "kt_ripple", "gravity", "cable_spring", "current_lag",
         "two_mass")
PAIRS = tuple(pair for pair in itertools.combinations(SEVEN, 2) if "current_lag" not in pair)


def declared(data: dict[str, Any], truth: Truth) -> bool:
    """A named cause says it is not separable from ``truth``'s effect, with an interval of
    its key parameter that holds the truth."""
    for cause in data["causes"]:
        other = cause.get("not_separable_from", {}).get(truth.effect)
        if cause.get("separable") is False and "note" in cause and other is not None:
            interval = other["uncertainty"][truth.key]["ci95"]
            if interval is not None and interval[0] <= truth.truth <= interval[1]:
                return True
    return False


@settings(DETERMINISTIC, max_examples=12)
@given(
    pair=st.sampled_from(PAIRS),
    sizes=st.lists(st.floats(0.0, 1.0), min_size=4, max_size=4),
    inertia=st.floats(0.002, 0.006),
    viscous=st.floats(0.003, 0.008),
    coulomb=st.floats(0.015, 0.03),
    order=st.integers(24, 120),
    seed=st.integers(0, 2**16),
)
def test_two_hidden_effects_are_named_and_recovered(
        pair: tuple[str, str], sizes: list[float], inertia: float, viscous: float,
        coulomb: float, order: int, seed: int) -> None:
    effects = ((pair[0], sizes[0], sizes[1]), (pair[1], sizes[2], sizes[3]))
    hidden = plant_with(inertia, viscous, coulomb, effects, order)
    data = report(diagnose(record(hidden.params, seed=seed)))
    causes = {cause["name"]: cause for cause in data["causes"]}
    for truth in hidden.truths:
        cause = causes.get(truth.effect)
        if cause is not None and recovered(cause, truth.key, truth.truth):
            assert cause["gain"]["significant"]
            continue
        assert declared(data, truth), (truth, {n: (c["parameters"], c.get("not_separable_from"))
                                               for n, c in causes.items()})
    for name, cause in causes.items():
        aliases = set(cause.get("not_separable_from", {}))
        assert name in pair or aliases & set(pair), (name, list(causes))
        assert math.isfinite(cause["gain"]["rms_reduction"])
