"""The statistics of a comparison: Holm, Student-t p-values, Welch–Satterthwaite, and the
rule that keeps shared budget lines out of the difference."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from scipy import stats

from hil.compare.budget import Sharing, classify, difference_budget
from hil.compare.certificates import BudgetLine, read_certificate
from hil.compare.statistics import critical_t, holm, t_p_value
from hil.compare.verdict import Verdict, compare_sides
from tests.compare.certificate_factory import certificate, result, write

PROTOCOLS = ("current_loop", "gravity_cable", "inertia_friction", "torque_constant")


def test_holm_reproduces_the_worked_example() -> None:
    # Holm (1979) as Wikipedia works it: p = 0.01, 0.04, 0.03, 0.005 at alpha 0.05 rejects
    # H1 and H4 (0.005 ≤ 0.05/4, 0.01 ≤ 0.05/3, then 0.03 > 0.05/2 stops)
    adjusted = holm([0.01, 0.04, 0.03, 0.005])
    assert adjusted == pytest.approx([0.03, 0.06, 0.06, 0.02])
    assert [p <= 0.05 for p in adjusted] == [True, False, False, True]


def test_holm_adjusted_values_are_monotone_and_capped() -> None:
    assert holm([0.5, 0.4, 0.9]) == pytest.approx([1.0, 1.0, 1.0])
    assert holm([]) == []
    assert holm([0.02]) == [0.02]


def test_p_values_follow_student_t() -> None:
    assert t_p_value(2.0, 1.0, math.inf) == pytest.approx(0.0455, abs=1e-4)
    assert t_p_value(-2.228, 1.0, 10) == pytest.approx(0.05, abs=2e-4)  # t₀.₉₇₅(10) = 2.228
    assert t_p_value(0.0, 1.0, 5) == 1.0
    assert t_p_value(1e-9, 0.0, 5) == 0.0
    assert critical_t(0.05, 10) == pytest.approx(2.228, abs=1e-3)
    assert critical_t(0.05, math.inf) == pytest.approx(1.960, abs=1e-3)


SOURCES = [  # every budget source the code writes (grep hil/ for Component( and from_change)
    ("measurement noise: scatter of the data (Type A)", "A", Sharing.INDEPENDENT),
    ("current-loop time constant τ taken out (current_loop)", "B", Sharing.INDEPENDENT),
    ("cable hysteresis loop h taken out (gravity_cable)", "B", Sharing.INDEPENDENT),
    ("load stiffness dL/dθ at the sines' centre (gravity_cable: m·g·e, φ, k_cable)", "B",
     Sharing.INDEPENDENT),
    ("torque-reporting gain, shaft/reported (torque_constant)", "B", Sharing.INDEPENDENT),
    ("method: error over 50 simulated units beyond Type A (mean −0.053 % corrected)", "B",
     Sharing.SHARED),
    ("allowance for physics the simulator lacks (profile allowance_pct, rectangular)", "B",
     Sharing.SHARED),
    ("torque sensor calibration constant (station)", "B", Sharing.SHARED),
    ("cable hysteresis loop h, with the s₀ fitted with it, taken out (gravity_cable)", "B",
     Sharing.INDEPENDENT),
    ("cable hysteresis loop's angle s₀ beyond h taken out (gravity_cable)", "B",
     Sharing.INDEPENDENT),
    ("cable hysteresis loop's angle s₀, second order (gravity_cable)", "B",
     Sharing.INDEPENDENT),
    ("no K_t ripple above the detection limit 0.33 % (rectangular between 0 and it)", "B",
     Sharing.SHARED),
    ("resolution of the sample grid (rectangular)", "B", Sharing.SHARED),
    ("encoder resolution (rectangular, LSB/√12)", "B", Sharing.SHARED),
    ("scatter of 5 repeated steps (Type A)", "A", Sharing.INDEPENDENT),
]


@pytest.mark.parametrize(("source", "kind", "expected"), SOURCES)
def test_every_budget_source_is_shared_or_independent_by_the_stated_rule(
    source: str, kind: str, expected: Sharing
) -> None:
    line = BudgetLine(source=source, kind=kind, standard_uncertainty=1.0,  # type: ignore[arg-type]
                      sensitivity=1.0, dof=math.inf)
    assert classify(line, protocols=PROTOCOLS)[0] is expected
    assert classify(line, protocols=PROTOCOLS, same_unit=False)[0] is Sharing.INDEPENDENT


def test_a_protocol_reference_counts_only_for_a_protocol_that_ran() -> None:
    line = BudgetLine(source="gain taken out (resonance)", kind="B", standard_uncertainty=1.0,
                      sensitivity=1.0, dof=math.inf)
    assert classify(line, protocols=("resonance",))[0] is Sharing.INDEPENDENT
    assert classify(line, protocols=("current_loop",))[0] is Sharing.SHARED


def _pair(tmp_path: Path, baseline: dict[str, object], candidate: dict[str, object]
          ) -> tuple[object, object]:
    b = read_certificate(write(tmp_path / "b.json", certificate(results=[baseline])))
    c = read_certificate(write(tmp_path / "c.json", certificate(results=[candidate])))
    return b.results["x"], c.results["x"]


def test_shared_lines_cancel_and_independent_lines_add(tmp_path: Path) -> None:
    b, c = _pair(tmp_path, result("x", 1.0, u_a=0.003, u_method=0.04),
                 result("x", 1.0, u_a=0.004, u_method=0.04))
    same = difference_budget(b, c, protocols=PROTOCOLS)  # type: ignore[arg-type]
    assert same.standard_uncertainty == pytest.approx(0.005)  # √(0.003² + 0.004²)
    other = difference_budget(b, c, protocols=PROTOCOLS, same_unit=False)  # type: ignore[arg-type]
    assert other.standard_uncertainty == pytest.approx(math.sqrt(0.005**2 + 2 * 0.04**2))


def test_a_shared_line_of_different_size_leaves_its_difference(tmp_path: Path) -> None:
    # a relative method scatter on two different values: fully correlated, |c_c − c_b| stays
    b, c = _pair(tmp_path, result("x", 1.0, u_a=0.003, u_method=0.040),
                 result("x", 1.5, u_a=0.004, u_method=0.060))
    budget = difference_budget(b, c, protocols=PROTOCOLS)  # type: ignore[arg-type]
    assert budget.standard_uncertainty == pytest.approx(math.sqrt(0.005**2 + 0.020**2))


def test_degrees_of_freedom_follow_welch_satterthwaite(tmp_path: Path) -> None:
    b, c = _pair(tmp_path, result("x", 1.0, u_a=1.0, dof_a=4),
                 result("x", 1.0, u_a=1.0, dof_a=9))
    budget = difference_budget(b, c, protocols=PROTOCOLS)  # type: ignore[arg-type]
    assert budget.dof == pytest.approx(2.0**2 / (1 / 4 + 1 / 9))


def test_the_p_value_uses_the_difference_budget(tmp_path: Path) -> None:
    # Δ = 0.02 with u(Δ) = 0.005 on 20 + 20 dof: t = 4; the method line (0.04) cancels
    b = write(tmp_path / "b" / "U-1" / "certificate.json",
              certificate(results=[result("x", 1.0, u_a=0.0035355, u_method=0.04)]))
    c = write(tmp_path / "c" / "U-1" / "certificate.json",
              certificate(results=[result("x", 1.02, u_a=0.0035355, u_method=0.04)]))
    from hil.compare.certificates import load_side

    (row,) = compare_sides(load_side(b), load_side(c)).rows
    assert row.budget is not None
    assert row.budget.dof == pytest.approx(40)
    assert row.p_value == pytest.approx(2 * stats.t.sf(4.0, 40), rel=1e-3)
    assert row.verdict is Verdict.CHANGED


def test_a_measured_repeatability_excess_adds_one_independent_line_per_run(
    tmp_path: Path,
) -> None:
    from hil.compare.repeatability import Repeatability

    b, c = _pair(tmp_path, result("x", 1.0, u_a=0.003), result("x", 1.0, u_a=0.004))
    extra = Repeatability(name="x", relative=True, scatter=0.006, pairs=20)
    budget = difference_budget(b, c, protocols=PROTOCOLS,  # type: ignore[arg-type]
                               repeatability=extra)
    assert budget.standard_uncertainty == pytest.approx(math.sqrt(0.005**2 + 2 * 0.006**2))
    assert budget.lines[-1].sharing is Sharing.INDEPENDENT
    assert "identical-firmware reruns" in budget.lines[-1].source
