"""Nelson's eight tests, each index checked on a worked sequence.

The rules as Nelson (1984), "The Shewhart control chart — tests for special causes",
J. Quality Technology 16(4) 237–239, states them and as Montgomery (Introduction to SQC,
6th ed., ch. 5), the NIST/SEMATECH e-Handbook (§6.3.2) and SAS/QC ("Tests for Special
Causes", SHEWHART procedure) reprint them; the only published per-rule index listing found
(Minitab's I-MR example on EXH_QC.MTW) comes without its data, so each sequence below is
worked by hand from the definitions: values in σ units about a centre of 0 unless said,
indices 0-based, each expected index derived in the comment.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from hil.errors import InputError
from hil.fleet.rules import DEFAULT_RULES, nelson_rules, parse_rules


def hits(values: list[float], rule: int, *, sigma: float = 1.0) -> list[int]:
    return nelson_rules(values, centre=0.0, sigma=sigma, rules=[rule])[rule]


def test_rule_1_one_point_beyond_3_sigma() -> None:
    # exactly 3σ is not beyond; 3.01 (index 2) and −3.5 (index 3) are
    assert hits([0.0, 3.0, 3.01, -3.5, 2.99, 0.0], 1) == [2, 3]


def test_rule_2_nine_in_a_row_on_one_side() -> None:
    # index 0 below, 1…10 above: the 9th above is index 9, the 10th index 10
    assert hits([-0.5] + [0.5] * 10, 2) == [9, 10]
    assert hits([-0.2] * 9, 2) == [8]
    # a point on the centre line belongs to neither side: 5 + 5 never makes nine
    assert hits([0.5] * 5 + [0.0] + [0.5] * 5, 2) == []
    assert hits([0.5] * 8, 2) == []


def test_rule_3_six_in_a_row_increasing_or_decreasing() -> None:
    # raw values, zones do not matter: 0…6 rises from index 0; the 6th point is index 5
    assert hits([0, 1, 2, 3, 4, 5, 6], 3, sigma=10.0) == [5, 6]
    assert hits([5, 4, 3, 2, 1, 0], 3) == [5]
    # a tie breaks the trend: after 2, 2 only 2, 3, 4, 5 rise (4 points)
    assert hits([0, 1, 2, 2, 3, 4, 5], 3) == []
    # five points rising is not enough
    assert hits([0, 1, 2, 3, 4], 3) == []


def test_rule_4_fourteen_alternating() -> None:
    assert hits([0.0, 1.0] * 7, 4) == [13]
    assert hits([0.0, 1.0] * 7 + [0.0], 4) == [13, 14]
    # thirteen points alternate: no hit; a repeated value breaks the zig-zag
    assert hits([0.0, 1.0] * 6 + [0.0], 4) == []
    assert hits([0.0, 1.0] * 3 + [1.0] + [0.0, 1.0] * 4, 4) == []


def test_rule_5_two_of_three_beyond_2_sigma() -> None:
    # A _ A: the third point completes the pattern
    assert hits([2.5, 0.0, 2.5], 5) == [2]
    # A A at the start: complete at the second point; A A C does not fire at C
    assert hits([2.5, 2.5, 0.0], 5) == [1]
    # three in a row beyond: indices 1 and 2 (each the second of two in its window)
    assert hits([0.0, 2.1, 2.2, 2.3], 5) == [2, 3]
    # opposite sides do not count together; 2σ exactly is not beyond; A C C A is too far
    assert hits([-2.5, 2.5, 0.0], 5) == []
    assert hits([2.0, 2.0, 2.0], 5) == []
    assert hits([2.5, 0.0, 0.0, 2.5], 5) == []
    assert hits([-2.5, -0.5, -2.6], 5) == [2]


def test_rule_6_four_of_five_beyond_1_sigma() -> None:
    assert hits([1.5, 1.5, 0.0, 1.5, 1.5], 6) == [4]
    assert hits([1.5, 1.5, 1.5, 1.5], 6) == [3]  # four of the first four
    # B B B C B: the 5th point completes it; _ B B B C: the C completes nothing
    assert hits([1.5, 1.5, 1.5, 0.5, 1.5], 6) == [4]
    assert hits([0.0, 1.5, 1.5, 1.5, 0.5], 6) == []
    # the odd one out may lie anywhere, even beyond 1σ on the other side …
    assert hits([-1.2, -1.2, 1.2, -1.2, -1.2], 6) == [4]
    # … but the four must share a side: 3 below and 2 above is no pattern
    assert hits([-1.2, -1.2, 1.2, 1.2, -1.2], 6) == []
    assert hits([-1.2, -1.2, -0.2, -1.2, -1.2, -1.3], 6) == [4, 5]


def test_rule_7_fifteen_within_1_sigma() -> None:
    inside = [0.9, -0.9] * 7 + [0.9]  # 15 points
    assert hits(inside, 7) == [14]
    assert hits([*inside, -0.1], 7) == [14, 15]
    # exactly 1σ is not within: index 7 at 1.0 leaves runs of 7 and 7
    assert hits([*inside[:7], 1.0, *inside[8:]], 7) == []


def test_rule_8_eight_beyond_1_sigma_on_both_sides() -> None:
    assert hits([1.5, -1.5] * 4, 8) == [7]
    assert hits([1.5] * 8, 8) == []  # all on one side
    assert hits([1.5, -1.5, 1.5, 0.5, -1.5, 1.5, -1.5, 1.5], 8) == []  # one in zone C
    assert hits([0.0] + [1.5] * 7 + [-1.5], 8) == [8]


def test_selection_and_default() -> None:
    assert DEFAULT_RULES == (1, 2, 5, 6)
    assert parse_rules("all") == tuple(range(1, 9))
    assert parse_rules("6, 1,1") == (1, 6)
    assert set(nelson_rules([0.0, 1.0], centre=0.0, sigma=1.0)) == {1, 2, 5, 6}
    for bad in ("9", "x", "", [0]):
        with pytest.raises(InputError, match="rules"):
            parse_rules(bad)
    with pytest.raises(InputError, match="positive σ"):
        nelson_rules([1.0, 2.0], centre=0.0, sigma=0.0)


# Per-point false-signal probabilities for independent N(centre, σ²) points far from the
# start of the series (exact for these definitions):
Q1, Q2, Q3 = (float(stats.norm.sf(k)) for k in (1.0, 2.0, 3.0))
RATE = {
    1: 2 * Q3,
    2: 2 * 0.5**9,
    5: 2 * Q2 * (1 - (1 - Q2) ** 2),               # this one beyond, ≥ 1 of the 2 before
    6: 2 * Q1 * (4 * Q1**3 * (1 - Q1) + Q1**4),      # this one beyond, ≥ 3 of the 4 before
}


@settings(max_examples=5)
@given(seed=st.integers(0, 2**32 - 1))
def test_in_control_data_fire_at_the_stated_rate(seed: int) -> None:
    """200 000 in-control points: each default rule's hit count within 5 SD of its expected
    rate. Hits cluster (a run of 10 gives two rule-2 hits); a cluster size that is
    geometric with continuation ½ makes Var ≈ 3·N·p, the SD used here for every rule."""
    n = 200_000
    x = np.random.default_rng(seed).standard_normal(n)
    found = nelson_rules(x, centre=0.0, sigma=1.0, rules=DEFAULT_RULES)
    for rule, p in RATE.items():
        expected, sd = n * p, np.sqrt(3 * n * p)
        assert abs(len(found[rule]) - expected) <= 5 * sd, (rule, len(found[rule]), expected)


def _oracle(z: list[float], rule: int) -> list[int]:
    """Each rule written out as a plain loop over the definitions above (an independent
    re-statement, not the vectorised code under test)."""
    out = []
    for i in range(len(z)):
        def last(k: int, i: int = i) -> list[float]:
            return z[max(0, i - k + 1): i + 1]

        w = last({2: 9, 3: 6, 4: 14, 7: 15, 8: 8}.get(rule, 1))
        if rule == 1:
            fired = abs(z[i]) > 3
        elif rule == 2:
            fired = len(w) == 9 and (all(v > 0 for v in w) or all(v < 0 for v in w))
        elif rule == 3:
            steps = [b - a for a, b in itertools.pairwise(w)]
            fired = len(w) == 6 and (all(s > 0 for s in steps) or all(s < 0 for s in steps))
        elif rule == 4:
            steps = [b - a for a, b in itertools.pairwise(w)]
            fired = len(w) == 14 and all(
                s * t < 0 for s, t in itertools.pairwise(steps))
        elif rule in (5, 6):
            k, m, bound = (2, 3, 2.0) if rule == 5 else (4, 5, 1.0)
            window = last(m)
            fired = any(
                sign * z[i] > bound and sum(sign * v > bound for v in window) >= k
                for sign in (1, -1))
        elif rule == 7:
            fired = len(w) == 15 and all(abs(v) < 1 for v in w)
        else:
            fired = (len(w) == 8 and all(abs(v) > 1 for v in w)
                     and any(v > 1 for v in w) and any(v < -1 for v in w))
        if fired:
            out.append(i)
    return out


# values on a coarse grid so that ties, zone boundaries and the centre line all occur
grid = st.integers(-7, 7).map(lambda k: k / 2)


@settings(max_examples=300)
@given(z=st.lists(grid, min_size=0, max_size=60))
def test_every_rule_matches_its_definition_written_as_a_loop(z: list[float]) -> None:
    found = nelson_rules(z, centre=0.0, sigma=1.0, rules="all")
    for rule in range(1, 9):
        assert found[rule] == _oracle(z, rule), rule


@given(z=st.lists(st.floats(-5, 5), min_size=0, max_size=40),
       scale=st.floats(0.01, 100), offset=st.floats(-1e3, 1e3))
def test_rules_do_not_care_about_units_or_sign(z: list[float], scale: float,
                                              offset: float) -> None:
    """x → offset ± scale·x with the centre and σ moved alike fires at the same points."""
    base = nelson_rules(z, centre=0.0, sigma=1.0, rules="all")
    for sign in (1.0, -1.0):
        x = [offset + sign * scale * v for v in z]
        moved = nelson_rules(x, centre=offset, sigma=scale, rules="all")
        for rule in (2, 3, 4, 7, 8):  # no boundary arithmetic: exact
            assert moved[rule] == base[rule], (rule, sign)
