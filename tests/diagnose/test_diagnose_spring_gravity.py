"""A cable spring against gravity (issue 29): two pairs of the benchmark, traced.

A spring's torque ``k·(θ − θ₀)`` has no curvature over the travel; gravity's
``m·g·e·cos(θ + φ)`` has ``−`` its own value as its second derivative. Where the best
subset's held-out RMS and BIC could not tell the two apart, the screening path decided:
the effect met first stayed (docs/diagnose.md, "Recordings no single simulator shapes").
"""

from __future__ import annotations

import pytest
from diagnose_simdata import plant_with, record
from test_diagnose_hidden import recovered

from hil.diagnose.core import diagnose
from hil.diagnose.report import report
from plant_sim.variant import Variant

pytestmark = pytest.mark.slow(seconds=30)


def test_a_spring_beside_a_lag_is_not_named_gravity() -> None:
    """The variant benchmark's pair 18 (seed 7): before the lag was in the model the spring
    failed its plausibility, so it was proposed beside gravity only, and gravity (met first)
    was named with the lag. Proposed in gravity's place beside the lag it is named."""
    hidden = plant_with(0.003646584599627554, 0.007613797880842338, 0.016030730281827922,
                        (("cable_spring", 0.519514819877859, 0.9509381955818498),
                         ("current_lag", 0.25099924666475815, 0.8060391472621088)), 48)
    variant = Variant(integrator="heun", substeps=1, friction_law="static",
                      stick_band_rad_s=0.0007061532212287184, estimator="moving_average",
                      moving_average_taps=5, setpoint_weight=0.635551300590082,
                      torque_filter_hz=0.0, sample_rate_hz=1000.0, period_jitter_rel=0.0,
                      apply_delay_rel=0.18692929820691248, encoder_counts_per_rev=2**20,
                      noise_colour="white", torque_tap="command",
                      shaft_noise_nm=0.000176139756002205)
    data = report(diagnose(record(hidden.params, seed=28180, variant=variant)))
    causes = {cause["name"]: cause for cause in data["causes"]}
    assert set(causes) == {"cable_spring", "current_lag"}
    spring = hidden.truths[0]
    assert recovered(causes["cable_spring"], spring.key, spring.truth)


def test_a_gravity_with_curvature_is_not_named_a_spring() -> None:
    """The pairs benchmark's case 37 (seed 7, this project's simulator): a gravity of
    0.036 N·m at φ = −0.32 rad, mostly ``cos θ``, curved by about 6 mN·m over the ±0.6 rad
    travel. A spring with its Dahl loop and its zero at −3.3 rad (a constant and a slope)
    came within 1 % of the gravity's held-out RMS and won on BIC beside a lag; the torque
    it leaves is curved (t ≈ 5.8 against the jackknife's 2.95 at 99 %), which no spring
    makes, so gravity is named."""
    hidden = plant_with(0.005756719834763524, 0.0072151253342079315, 0.026656737135797727,
                        (("gravity", 0.6412291106098151, 0.1844456424465789),
                         ("current_lag", 0.7594944652808059, 0.7576906645183887)), 82)
    data = report(diagnose(record(hidden.params, seed=25887)))
    causes = {cause["name"]: cause for cause in data["causes"]}
    assert set(causes) == {"gravity", "current_lag"}
    gravity = hidden.truths[0]
    assert recovered(causes["gravity"], gravity.key, gravity.truth)


def test_a_spring_beside_k_t_ripple_is_not_named_gravity() -> None:
    """The pairs benchmark's case 75 (seed 7, this project's simulator; the same unit on
    the variant simulator failed too): a 0.021 N·m/rad spring zeroed at −0.02 rad, which
    over the ±0.6 rad travel gravity at φ ≈ −π/2 matches within 0.2 mN·m. Gravity was met
    first, the ripple's orders and weight were searched beside it, and the spring was
    judged beside a ripple searched on the base model (traced on the variant's recording:
    BIC 4 apart alone, 1.8 % worse held out beside that ripple). With the ripple searched
    again beside the spring the two tie (3.330 and 3.332 mN·m there) and the spring is
    named."""
    hidden = plant_with(0.005405924361874867, 0.006777630479251498, 0.020050268975638743,
                        (("kt_ripple", 0.13222302482887627, 0.1842722293348068),
                         ("cable_spring", 0.30391802901193854, 0.44751572422059904)), 75)
    data = report(diagnose(record(hidden.params, seed=5078)))
    causes = {cause["name"]: cause for cause in data["causes"]}
    assert set(causes) == {"cable_spring", "kt_ripple"}
    for truth in hidden.truths:
        assert recovered(causes[truth.effect], truth.key, truth.truth)
