"""Stop when the uncertainty is reached: the rule, the pooling of repeated runs, and the
J/B/T_c sines on the simulator run once on a clean unit and again on a noisy one."""

from __future__ import annotations

import dataclasses
import math

import pytest

import hil.suite.inertia_friction as sine
from hil.config import ConfigTable
from hil.drives.sim import SimDrive
from hil.errors import IdentificationError, ProfileError
from hil.identify.estimate import Component, Estimate
from hil.measurement import MethodBiasMap
from hil.profile import load_profile
from hil.suite.stop_rule import StopRule, decide, pooled, repeat_until, target_expanded_u

PROFILE = load_profile("demo_gimbal_elevation")
NO_MAP = MethodBiasMap(source="off", sha256="", entries={})


def _estimate(value: float, u_a: float, u_b: float) -> Estimate:
    lines = (Component(source="noise", kind="A", standard_uncertainty=u_a, unit="N·m", dof=7),
             Component(source="input", kind="B", standard_uncertainty=u_b, unit="N·m"))
    return Estimate(name="coulomb_nm", value=value, standard_uncertainty=math.hypot(u_a, u_b),
                    unit="N·m", dof=7, budget=lines)


def test_pooled_repeats_average_the_type_a_lines_and_keep_the_shared_inputs() -> None:
    runs = [_estimate(0.020, 4e-4, 1e-4), _estimate(0.021, 4e-4, 1e-4)]
    both = pooled(runs)
    assert both.value == pytest.approx(0.0205)
    noise, shared = both.budget
    assert noise.contribution == pytest.approx(4e-4 / math.sqrt(2))
    assert noise.dof == 14
    assert shared.contribution == pytest.approx(1e-4)
    assert both.standard_uncertainty == pytest.approx(math.hypot(4e-4 / math.sqrt(2), 1e-4))
    assert pooled(runs[:1]) is runs[0]


def test_the_rule_judges_the_certificates_u_against_its_share_of_the_tolerance() -> None:
    spec = PROFILE.measurement("coulomb_nm")  # 0.020 ± 30 %: half-width 0.006 N·m
    rule = StopRule(fraction=0.25, max_runs=2, results=None)
    assert target_expanded_u(spec, 0.25) == pytest.approx(0.0015)
    clean = decide({"coulomb_nm": _estimate(0.02, 3e-4, 1e-4)}, {"coulomb_nm": spec}, NO_MAP,
                   rule, runs=1)
    assert not clean.again
    assert "every U ≤ 0.25 × the tolerance half-width after 1 run" in clean.reason
    noisy = decide({"coulomb_nm": _estimate(0.02, 9e-4, 1e-4)}, {"coulomb_nm": spec}, NO_MAP,
                   rule, runs=1)
    # U = k·u with Student's k for 7 degrees of freedom: 2.43 × 0.00091
    assert noisy.again
    assert noisy.reason == "run 2 of at most 2: after 1 run, coulomb_nm U = 0.0022 > 0.0015 N·m"
    last = decide({"coulomb_nm": _estimate(0.02, 9e-4, 1e-4)}, {"coulomb_nm": spec}, NO_MAP,
                  rule, runs=2)
    assert not last.again
    assert last.reason.startswith("max_runs = 2 reached with coulomb_nm")
    stuck = decide({"coulomb_nm": _estimate(0.02, 9e-4, 1e-3)}, {"coulomb_nm": spec}, NO_MAP,
                   rule, runs=1)  # the Type B line alone: U = 2 × 0.001 > 0.0015
    assert stuck.reason.endswith("(runs cannot take it below 0.002: Type B and shared lines)")
    other = dataclasses.replace(rule, results=("inertia_kg_m2",))
    assert not decide({"coulomb_nm": _estimate(0.02, 9e-4, 1e-4)}, {"coulomb_nm": spec},
                      NO_MAP, other, runs=1).again  # not a judged result


def test_the_rule_is_read_from_the_protocol_table_and_bad_values_are_refused() -> None:
    def table(**values: object) -> ConfigTable:
        return ConfigTable(values, table="[protocols.inertia_friction]", source="unit.toml")

    assert StopRule.from_settings(table()) is None
    rule = StopRule.from_settings(table(stop_at_u_fraction=0.25, max_runs=4,
                                        stop_results="inertia_kg_m2, coulomb_nm"))
    assert rule == StopRule(fraction=0.25, max_runs=4, results=("inertia_kg_m2", "coulomb_nm"))
    misspelt = StopRule.from_settings(table(stop_at_u_fraction=0.25, stop_results="coulomb"))
    assert misspelt is not None
    with pytest.raises(ProfileError, match=r"^unit.toml: \[protocols.inertia_friction\] "
                                           r"'stop_results': 'coulomb' is not a result of this "
                                           r"protocol \(its results: coulomb_nm\)$"):
        repeat_until(lambda: {"coulomb_nm": _estimate(0.02, 3e-4, 1e-4)}, specs={},
                     method_bias=NO_MAP, rule=misspelt)
    with pytest.raises(ProfileError, match="max_runs"):
        StopRule.from_settings(table(stop_at_u_fraction=0.25, max_runs=0))
    with pytest.raises(ProfileError, match="stop_at_u_fraction"):
        StopRule.from_settings(table(stop_at_u_fraction=-1.0))


@pytest.mark.parametrize(("noise_nm", "runs"), [(0.0015, 1), (0.03, 3)])
def test_the_sines_run_again_only_while_the_noise_keeps_u_above_its_target(
        noise_nm: float, runs: int) -> None:
    assert PROFILE.plant is not None
    plant = dataclasses.replace(PROFILE.plant, torque_noise_nm=noise_nm)
    specs = {"inertia_kg_m2": PROFILE.measurement("inertia_kg_m2")}  # ±15 %: 0.00054
    rule = StopRule(fraction=0.05, max_runs=3, results=("inertia_kg_m2",))  # U ≤ 2.7e-5
    with SimDrive(plant, firmware=PROFILE.firmware, limits=PROFILE.limits,
                  fs_hz=PROFILE.sample_rate_hz, seed=4) as drive:
        drive.enable()
        spec = sine.Spec.from_profile(PROFILE, drive.info)
        centre = (PROFILE.limits.travel_min_rad + PROFILE.limits.travel_max_rad) / 2
        drive.run(sine.move_to_centre(spec, centre, position_rad=drive.status().position_rad))

        def run_once() -> dict[str, Estimate]:
            found = sine.analyse([drive.run(e) for e in sine.excitation(spec)], spec)
            return {e.name: e for e in (found.inertia, found.viscous, found.coulomb)}

        found, decision = repeat_until(run_once, specs=specs, method_bias=NO_MAP, rule=rule)
    assert decision.runs == runs
    assert found["inertia_kg_m2"].value == pytest.approx(
        plant.inertia_kg_m2 / (1 + plant.torque_constant_error_rel), rel=0.05)
    if runs == 1:
        assert "every U ≤" in decision.reason
    else:
        assert decision.reason.startswith("max_runs = 3 reached with inertia_kg_m2 U =")


def test_a_type_a_line_every_run_shares_is_not_divided_by_the_number_of_runs() -> None:
    """The tracking feedforward's u (an earlier result's, Type A) is the same error in each
    run: pooled like a Type B line."""
    def run(value: float) -> Estimate:
        lines = (Component(source="noise", kind="A", standard_uncertainty=4e-4, unit="N·m",
                           dof=7),
                 Component(source="earlier u [with feedforward]", kind="A",
                           standard_uncertainty=3e-4, unit="N·m"))
        return Estimate(name="coulomb_nm", value=value, standard_uncertainty=5e-4,
                        unit="N·m", dof=7, budget=lines)

    noise, shared = pooled([run(0.020), run(0.021)], shared=("earlier u",)).budget
    assert noise.contribution == pytest.approx(4e-4 / math.sqrt(2))
    assert shared.contribution == pytest.approx(3e-4)
    assert shared.source == "earlier u [with feedforward]"


def test_a_run_whose_budget_has_other_lines_is_left_out_and_the_rule_says_so() -> None:
    """A detection in one run and only a bound in the next are not repeats of one
    measurement: the protocol keeps the runs before and stops."""
    bound = Estimate(name="coulomb_nm", value=0.02, standard_uncertainty=1e-3, unit="N·m",
                     budget=(Component(source="bound", kind="B", standard_uncertainty=1e-3,
                                       unit="N·m"),))
    runs = iter([_estimate(0.02, 9e-4, 1e-4), bound])
    rule = StopRule(fraction=0.25, max_runs=3, results=None)
    found, decision = repeat_until(lambda: {"coulomb_nm": next(runs)},
                                   specs={"coulomb_nm": PROFILE.measurement("coulomb_nm")},
                                   method_bias=NO_MAP, rule=rule)
    assert decision.runs == 1
    assert decision.reason.startswith("run 2 left out: its coulomb_nm has other budget lines")
    assert found["coulomb_nm"].value == 0.02
    with pytest.raises(IdentificationError, match="budgets differ"):
        pooled([_estimate(0.02, 9e-4, 1e-4), bound])


def test_a_streamed_run_is_judged_with_its_paths_method_line() -> None:
    """τ over a 1 kHz stream gets its path's method line on the certificate (a band of
    |bias| + 2·scatter: ±2.9 % of τ for the point-sampled torque, against the simulator's
    0.05 % scatter), so the stop rule judges the run's U with that line too: the same
    estimate that stops under the simulator's line runs again under the stream's (the
    stop rule used the simulator's line for every path before)."""
    from hil.measurement import load_method_bias

    name = "current_loop_time_constant_ms"
    spec = PROFILE.measurement(name)  # 0.3 ms ± 0.09: half-width 0.09 ms
    shipped = load_method_bias(axis="elevation")
    path = "one row per 4 control periods, torque instantaneous"
    noise = Component(source="phase noise", kind="A", standard_uncertainty=1e-3, unit="ms",
                      dof=30)
    tau = Estimate(name=name, value=0.3, standard_uncertainty=1e-3, unit="ms", dof=30,
                   budget=(noise,))
    # U target 0.0045 ms; U 0.0021 ms with the simulator's line, 0.010 with the stream's
    rule = StopRule(fraction=0.05, max_runs=3, results=None)
    main = decide({name: tau}, {name: spec}, shipped, rule, runs=1)
    streamed = decide({name: tau}, {name: spec}, shipped, rule, runs=1,
                      lines=lambda result: shipped.line(result, path=path))
    assert not main.again, main.reason
    assert streamed.again, streamed.reason
    assert "runs cannot take it below" in streamed.reason  # the band is Type B
