"""Hypothesis hides one effect (type and size drawn) in a simulated run; name it, recover it.

Identification data carry encoder quantisation (2^20 counts), torque noise, a filtered
velocity estimate and a closed velocity loop. The sizes are drawn from ranges this test
excitation can reveal; the diagnoser never sees the effect, its size or the truth. Draws
are derandomized and no example database is kept: the outcome depends on this file's
code only, not on the module's import name or on the tests run before it.
"""

from __future__ import annotations

import math
from typing import Any

import pytest
from diagnose_simdata import plant, plant_with, record
from hypothesis import Phase, given, settings
from hypothesis import strategies as st

from hil.diagnose.core import diagnose
from hil.diagnose.report import report

pytestmark = pytest.mark.slow(seconds=100)

#: Effects whose recovery this test requires. K_t ripple and the current-loop lag are
#: tested on their own below (issue 12: their biases, mended).
EFFECTS = ("offset", "asymmetric_friction", "stribeck", "cogging", "gravity", "cable_spring",
           "two_mass")
DETERMINISTIC = settings(derandomize=True, database=None, deadline=None,
                         phases=[Phase.explicit, Phase.generate])


def recovered(cause: dict[str, Any], key: str, truth: float) -> bool:
    """The key parameter within 15 % of the truth, or, where the report says the excitation
    cannot separate it from another parameter, the truth inside its 95 % interval."""
    value = cause["parameters"][key]
    if math.isclose(value, truth, rel_tol=0.15):
        return True
    interval = cause["uncertainty"].get(key, {}).get("ci95")
    return (cause.get("separable") is False and interval is not None
            and interval[0] <= truth <= interval[1] and "note" in cause)


@settings(DETERMINISTIC, max_examples=8)
@given(
    effect=st.sampled_from(EFFECTS),
    inertia=st.floats(0.002, 0.006),
    viscous=st.floats(0.003, 0.008),
    coulomb=st.floats(0.015, 0.03),
    size=st.floats(0.0, 1.0),
    detail=st.floats(0.0, 1.0),
    order=st.integers(24, 120),
    seed=st.integers(0, 2**16),
)
def test_hidden_effect_is_named_and_recovered(effect: str, inertia: float, viscous: float,
                                              coulomb: float, size: float, detail: float,
                                              order: int, seed: int) -> None:
    hidden = plant(inertia, viscous, coulomb, effect, size, detail, order)
    data = report(diagnose(record(hidden.params, seed=seed)))
    # a part of the cause before it (an asymmetric friction's constant) is not a cause
    names = [cause["name"] for cause in data["causes"] if "part_of" not in cause]
    assert names == [effect], names
    cause = data["causes"][0]
    assert hidden.key is not None
    assert recovered(cause, hidden.key, hidden.truth), (
        hidden.key, cause["parameters"][hidden.key], hidden.truth, cause["uncertainty"])
    if effect == "cogging":
        assert cause["parameters"]["periods_per_rev"] == order


@settings(DETERMINISTIC, max_examples=3)
@given(
    inertia=st.floats(0.002, 0.006),
    viscous=st.floats(0.003, 0.008),
    coulomb=st.floats(0.015, 0.03),
    seed=st.integers(0, 2**16),
)
def test_no_hidden_effect_names_none(inertia: float, viscous: float, coulomb: float,
                                     seed: int) -> None:
    hidden = plant(inertia, viscous, coulomb, None, 0.0, 0.0, 0)
    data = report(diagnose(record(hidden.params, seed=seed)))
    assert data["causes"] == [], [c["name"] for c in data["causes"]]
    assert data["unexplained"] is False, data["unexplained_structure"]["where"]
    base = data["base"]["parameters"]
    assert math.isclose(base["inertia_kg_m2"], inertia, rel_tol=0.1)
    assert math.isclose(base["coulomb_nm"], coulomb, rel_tol=0.1)


def test_current_lag_is_recovered_within_15_pct() -> None:
    """Was 1.19 ms for 1.5 ms (-21 %): the position's quantisation noise in the regressors
    shortened tau along the tau/lead valley (now compensated, hil/diagnose/lag.py)."""
    hidden = plant(0.005, 0.005, 0.02, "current_lag", 0.0, 0.5, 60)
    data = report(diagnose(record(hidden.params, seed=3)))
    assert data["causes"][0]["name"] == "current_lag"
    lag = data["causes"][0]["parameters"]["time_constant_s"]
    assert math.isclose(lag, hidden.truth, rel_tol=0.15), (lag, hidden.truth)


def test_kt_ripple_is_recovered_within_15_pct() -> None:
    """Was 0.095 for 0.12 (-21 %): the order search's periodogram was lifted by the chirp's
    misfit (large torque at one angle), and leaked neighbour orders shared the amplitude."""
    hidden = plant(0.005, 0.005, 0.02, "kt_ripple", 0.2, 0.9, 50)
    data = report(diagnose(record(hidden.params, seed=4)))
    assert data["causes"][0]["name"] == "kt_ripple"
    parameters = data["causes"][0]["parameters"]
    assert parameters["periods_per_rev"] == 25
    assert math.isclose(parameters["relative_amplitude"], hidden.truth, rel_tol=0.15), (
        parameters["relative_amplitude"], hidden.truth)


@settings(DETERMINISTIC, max_examples=3)
@given(
    inertia=st.floats(0.002, 0.006),
    viscous=st.floats(0.003, 0.008),
    coulomb=st.floats(0.015, 0.03),
    size=st.floats(0.0, 1.0),
    seed=st.integers(0, 2**16),
)
def test_hidden_lag_is_recovered_inside_its_interval(inertia: float, viscous: float,
                                                     coulomb: float, size: float,
                                                     seed: int) -> None:
    """τ within 15 % and its 95 % interval (jackknife, τ and the lead searched again)
    holding the truth: the Gauss–Newton interval before held it in 1 of 5 single lags."""
    hidden = plant(inertia, viscous, coulomb, "current_lag", size, 0.5, 60)
    data = report(diagnose(record(hidden.params, seed=seed)))
    assert [c["name"] for c in data["causes"]] == ["current_lag"]
    cause = data["causes"][0]
    lag = cause["parameters"]["time_constant_s"]
    assert math.isclose(lag, hidden.truth, rel_tol=0.15), (lag, hidden.truth)
    low, high = cause["uncertainty"]["time_constant_s"]["ci95"]
    assert low <= hidden.truth <= high, (low, high, hidden.truth)


def test_no_ripple_is_named_beside_a_strong_asymmetric_friction() -> None:
    """Was a 0.17 % K_t ripple (orders 41 and 16, held-out gain 1.2 %) beside a viscous
    friction 4.5 × stronger moving negative: the selection judged the ripple on the joint fit,
    where its columns, constants wherever the angle stands still (the chirp), took up the
    chirp's misfit (the encoder's quantisation in the inertia column). Now judged in two
    stages, the ripple from the rows where the angle sweeps (hil/diagnose/ripple.py)."""
    # Hypothesis's draw to the last digit: rounded to 5 digits, the old code names no ripple
    viscous = 0.0035776002529962366
    hidden = plant(0.0047748791596803584, viscous, 0.017344883015344034,
                   "asymmetric_friction", 0.9901311281201386, 0.02768748407926403, 28)
    data = report(diagnose(record(hidden.params, seed=342)))
    causes = [cause for cause in data["causes"] if "part_of" not in cause]
    assert [cause["name"] for cause in causes] == ["asymmetric_friction"]
    parameters = causes[0]["parameters"]
    assert math.isclose(parameters["viscous_neg"], hidden.truth, rel_tol=0.15)
    assert math.isclose(parameters["viscous_pos"], viscous, rel_tol=0.15)


def test_no_resonance_is_named_beside_the_strongest_stribeck_friction() -> None:
    """Was a 108 Hz resonance (ζ 0.1, the grid's top, load 11 %) beside T_s = 2·T_c with
    v_s = 0.04 rad/s and a large inertia: the axis stick-slips through the slow steps and
    most of the chirp, and the shaft filter took 1.7 % of the residual as a smooth fall of
    the effective inertia above 100 Hz (offered ζ up to 0.7 it took 0.7). Now searched up to
    ζ 0.7 and named only with ζ ≤ 0.2 (hil/diagnose/select.py, MAX_RESONANCE_DAMPING)."""
    hidden = plant(0.005120582598536086, 0.005404522172518298, 0.029761375156968424,
                   "stribeck", 0.99999, 0.9333236470186563, 33)
    data = report(diagnose(record(hidden.params, seed=3552)))
    assert [cause["name"] for cause in data["causes"]] == ["stribeck"]
    parameters = data["causes"][0]["parameters"]
    assert math.isclose(parameters["static_torque_nm"], hidden.truth, rel_tol=0.15)


#: Lag pairs of ``bench_diagnose --pairs --seed 7`` the lag came out low in, and why:
#: case 4, 2.69 ms for 3.58 ms (-25 %): the rows where the axis sticks (the chirp's top, the
#: slow steps) held 96 % of the residual and the friction columns switched half a sample
#: early; case 20, 2.10 ms for 3.01 ms (-30 %): sticking rows beside the shaft's dynamics
#: pulled τ along its valley with the lead. Now searched away from sticking and with the
#: friction delay (hil/diagnose/lag.py). Cases 25 and 100, beside a large inertia (J 0.0052,
#: 0.0060): -21 % and -19 %, the encoder's quantisation under-compensated (its stand-ins
#: re-quantised a low-passed position that still stepped where the axis crept); now drawn
#: through the position's changes of level first.
LAG_BESIDE = {
    "sticking_stribeck": ((0.00205, 0.00396, 0.02538), (("stribeck", 0.37, 0.004),
                                                        ("current_lag", 0.83, 0.154)), 109, 13146),
    "resonance": ((0.00285, 0.00758, 0.0276), (("current_lag", 0.604, 0.479),
                                               ("two_mass", 0.595, 0.659)), 81, 7366),
    "large_inertia_stribeck": ((0.00525, 0.00629, 0.02416), (("stribeck", 0.5744, 0.0397),
                                                             ("current_lag", 0.8017, 0.9601)),
                               46, 12533),
    "large_inertia_gravity": ((0.00599, 0.00378, 0.02719), (("gravity", 0.7833, 0.8918),
                                                            ("current_lag", 0.992, 0.266)),
                              59, 26941),
}


@pytest.mark.parametrize("case", sorted(LAG_BESIDE))
def test_current_lag_beside_another_effect_is_recovered_within_15_pct(case: str) -> None:
    (inertia, viscous, coulomb), effects, order, seed = LAG_BESIDE[case]
    hidden = plant_with(inertia, viscous, coulomb, effects, order)
    data = report(diagnose(record(hidden.params, seed=seed)))
    causes = {c["name"]: c for c in data["causes"]}
    truth = next(t for t in hidden.truths if t.effect == "current_lag")
    lag = causes["current_lag"]["parameters"]["time_constant_s"]
    assert math.isclose(lag, truth.truth, rel_tol=0.15), (lag, truth.truth)

