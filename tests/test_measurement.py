"""Decision rule, Type B method accuracy, profile validation."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hil.errors import ProfileError
from hil.identify.estimate import Estimate, coverage_factor
from hil.measurement import (
    Measurement,
    MethodBias,
    MethodBiasMap,
    Outcome,
    judge,
    load_method_bias,
    with_method_terms,
)
from hil.profile import MeasurementSpec, builtin_profile_path, load_profile

SPEC = MeasurementSpec(
    name="x",
    unit="N·m",
    nominal=1.0,
    lower_limit=0.9,
    upper_limit=1.1,
    marginal_fraction=0.2,
    accuracy_rel=0.03,
)


@pytest.mark.parametrize(
    ("value", "u", "expected"),
    [
        (1.0, 0.01, Outcome.PASS),
        (1.085, 0.001, Outcome.MARGINAL),  # inside the marginal band (last 20 % of ±0.1)
        (1.06, 0.03, Outcome.MARGINAL),  # value + U = 1.12 crosses the upper limit
        (1.11, 0.001, Outcome.FAIL),
        (0.89, 0.0, Outcome.FAIL),
        (math.nan, 0.0, Outcome.FAIL),
    ],
)
def test_decision_rule(value: float, u: float, expected: Outcome) -> None:
    estimate = Estimate(name="x", value=value, standard_uncertainty=u, unit="N·m")
    assert judge(estimate, SPEC) is expected


def test_one_sided_quantity_has_no_marginal_band_at_its_nominal() -> None:
    spread = MeasurementSpec(
        name="spread",
        unit="%",
        nominal=0.0,
        lower_limit=-0.001,
        upper_limit=5.0,
        marginal_fraction=0.2,
    )

    def outcome(value: float) -> Outcome:
        return judge(Estimate(name="s", value=value, standard_uncertainty=0.0, unit="%"), spread)

    assert outcome(0.3) is Outcome.PASS
    assert outcome(4.5) is Outcome.MARGINAL
    assert outcome(5.1) is Outcome.FAIL


SPREAD = MeasurementSpec(name="spread", unit="%", nominal=0.0, lower_limit=-0.001,
                         upper_limit=5.0, marginal_fraction=0.2)


@given(value=st.floats(0.0, 6.0), u=st.floats(0.0, 3.0))
def test_a_quantity_that_cannot_be_negative_is_never_marginal_for_its_lower_limit(
    value: float, u: float
) -> None:
    """Issue 30: a spread of 0.5 ± 1 % was MARGINAL against [-0.001, 5] (31 of 40 units of a
    foreign drive held for review), its interval reaching a limit no spread can cross. As
    non-negative: judged by the upper limit alone; as a signed quantity: as before."""
    estimate = Estimate(name="spread", value=value, standard_uncertainty=u / 2, unit="%")
    signed = judge(estimate, SPREAD)
    positive = judge(estimate, SPREAD, non_negative=True)
    upper_only = dataclasses.replace(SPREAD, lower_limit=-math.inf)
    assert positive is judge(estimate, upper_only)
    lower_side = value - estimate.expanded_uncertainty < SPREAD.lower_limit
    if not lower_side:
        assert positive is signed
    elif value + estimate.expanded_uncertainty <= SPREAD.upper_limit - 1.0:
        assert (signed, positive) == (Outcome.MARGINAL, Outcome.PASS)


def test_a_positive_lower_limit_still_binds_a_non_negative_quantity() -> None:
    ripple = dataclasses.replace(SPREAD, nominal=1.0, lower_limit=0.5, upper_limit=5.0)
    estimate = Estimate(name="ripple", value=0.7, standard_uncertainty=0.2, unit="%")
    assert judge(estimate, ripple, non_negative=True) is Outcome.MARGINAL


def test_coverage_factor_follows_student_t_for_few_degrees_of_freedom() -> None:
    assert coverage_factor(math.inf) == 2.0
    assert coverage_factor(7) == pytest.approx(2.43, abs=0.01)
    assert coverage_factor(2) == pytest.approx(4.53, abs=0.01)


def test_allowance_enters_as_a_named_rectangular_type_b_line() -> None:
    estimate = Estimate(name="x", value=2.0, standard_uncertainty=0.01, unit="N·m", dof=7)
    spec = dataclasses.replace(SPEC, allowance_rel=0.03)
    combined = with_method_terms(estimate, spec, None)
    assert combined.standard_uncertainty == pytest.approx(math.hypot(0.01, 0.06 / math.sqrt(3)))
    assert combined.dof > estimate.dof
    sources = [c.source for c in combined.budget]
    assert sources[0].startswith("measurement noise")
    assert "allowance" in sources[1]


def test_validated_accuracy_claim_is_not_an_uncertainty() -> None:
    estimate = Estimate(name="x", value=2.0, standard_uncertainty=0.01, unit="N·m", dof=7)
    assert SPEC.accuracy_rel
    assert with_method_terms(estimate, SPEC, None).standard_uncertainty == 0.01


@pytest.mark.parametrize(("relative", "expected"), [(True, 2.0 / 1.05), (False, 2.0 - 0.05)])
def test_known_method_bias_is_corrected_and_its_scatter_budgeted(
    relative: bool, expected: float
) -> None:
    estimate = Estimate(name="x", value=2.0, standard_uncertainty=0.01, unit="N·m", dof=7)
    bias = MethodBias(name="x", relative=relative, bias=0.05, scatter=0.02, units=200)
    corrected = with_method_terms(estimate, SPEC, bias)
    assert corrected.value == pytest.approx(expected)
    u_method = 0.02 * expected if relative else 0.02
    assert corrected.standard_uncertainty == pytest.approx(math.hypot(0.01, u_method))
    assert [c.kind for c in corrected.budget] == ["A", "B"]
    assert "200 simulated units" in corrected.budget[1].source


def test_method_bias_map_refuses_a_misspelt_key(tmp_path: Path) -> None:
    path = tmp_path / "bias.toml"
    path.write_text('population = "p"\n[results.azimuth.x]\nscale = "relative"\nbias = 0.1\n'
                    'scater = 0.01\nunits = 3\n', encoding="utf-8")
    with pytest.raises(ProfileError, match=r"\[results.azimuth.x\] lacks 'scatter'"):
        load_method_bias(path, axis="elevation")  # every axis' table is checked


def test_validated_coverage_reaches_the_certificate(tmp_path: Path) -> None:
    """The map's out-of-sample check, with its note, is stated with the result."""
    path = tmp_path / "bias.toml"
    path.write_text('population = "p"\n[results.elevation.x]\nscale = "relative"\n'
                    'bias = 0.1\nscatter = 0.01\nunits = 3\nvalidated_coverage = 0.89\n'
                    'validated_units = 100\nnote = "heavy tails"\n', encoding="utf-8")
    entry = load_method_bias(path, axis="elevation").entries["x"]
    assert entry.validation() == {"coverage": 0.89, "units": 100, "note": "heavy tails"}
    bare = MethodBias(name="x", relative=True, bias=0.0, scatter=0.0, units=3)
    assert bare.validation() is None


def test_a_second_simulators_check_reaches_the_certificate(tmp_path: Path) -> None:
    """Where a result's coverage depends on the simulator's drawn choices, the certificate
    says so after the map's own note (issue 30)."""
    path = tmp_path / "bias.toml"
    path.write_text('population = "p"\n[results.elevation.x]\nscale = "relative"\n'
                    'bias = 0.1\nscatter = 0.01\nunits = 3\nvalidated_coverage = 0.95\n'
                    'validated_units = 100\nnote = "heavy tails"\n'
                    'second_simulator = "88 %; missed on rate 4000 Hz jittered"\n',
                    encoding="utf-8")
    entry = load_method_bias(path, axis="elevation").entries["x"]
    validation = entry.validation()
    assert validation is not None
    assert validation["note"] == "heavy tails; 88 %; missed on rate 4000 Hz jittered"


def test_shipped_method_bias_map_loads() -> None:
    shipped = load_method_bias()
    assert all(e.units > 0 and e.scatter >= 0 for e in shipped.entries.values())


def _profile_text() -> str:
    return builtin_profile_path().read_text(encoding="utf-8")


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("[limits]", "[limit]", "missing table \\[limits\\]"),
        (
            "torque_nm = 0.5\ntravel",
            "torque_nm = -1\ntravel",
            "\\[limits\\] torque_nm = -1: must be > 0",
        ),
        (
            "inertia_kg_m2 = 0.0036\n",
            "inertia_kg_m = 0.0036\n",
            "lacks 'inertia_kg_m2' \\(found 'inertia_kg_m'",
        ),
        ("nominal = 0.0036\ntolerance_pct = 15", "nominal = 0.0036", "tolerance_pct"),
        ("sample_rate_hz = 4000.0", "sample_rate_hz = 'fast'", "must be a number, got 'fast'"),
    ],
)
def test_bad_profiles_name_file_and_key(tmp_path: Path, old: str, new: str, message: str) -> None:
    text = _profile_text()
    assert old in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    with pytest.raises(ProfileError, match=message) as caught:
        load_profile(path)
    assert str(path) in str(caught.value)


def test_missing_profile_and_unknown_builtin(tmp_path: Path) -> None:
    with pytest.raises(ProfileError, match="not found"):
        load_profile(tmp_path / "nope.toml")
    with pytest.raises(ProfileError, match="no built-in profile"):
        load_profile("no_such_unit")


@pytest.mark.parametrize(
    ("table", "read", "message"),
    [
        ({"speed_rad_s": "fast"}, lambda s: s.number("speed_rad_s", 0.1), "must be a number"),
        ({"blocks": 2.5}, lambda s: s.integer("blocks", 3), "must be an integer"),
        ({"band_hz": [1.0]}, lambda s: s.numbers("band_hz", count=2), "a list of 2 numbers"),
        ({}, lambda s: s.numbers("speeds_rad_s"), "lacks 'speeds_rad_s'"),
        ({"method": "magic"}, lambda s: s.choice("method", ("a", "b"), "a"), "one of a, b"),
    ],
)
def test_protocol_settings_name_table_and_key(table, read, message: str) -> None:  # type: ignore[no-untyped-def]
    from hil.config import ConfigTable

    settings = ConfigTable(table, table="[protocols.x]", source="unit.toml")
    with pytest.raises(ProfileError, match=message) as caught:
        read(settings)
    assert "unit.toml" in str(caught.value)
    assert "[protocols.x]" in str(caught.value)


def test_protocol_settings_refuse_unread_keys() -> None:
    from hil.config import ConfigTable

    settings = ConfigTable(
        {"speed_rad_s": 0.2, "sped_rad_s": 0.3}, table="[protocols.x]", source="unit.toml"
    )
    assert settings.number("speed_rad_s", 0.1) == 0.2
    with pytest.raises(ProfileError, match=r"unknown setting 'sped_rad_s'.*did you mean 'speed_r"):
        settings.done()


@pytest.mark.parametrize(
    ("value", "conforms", "shown"),
    [
        (1.0, True, "1.0000 ± 0.0020"),
        (1.085, True, "1.0850 ± 0.0020"),
        (1.11, False, "1.1100 ± 0.0020"),
        (math.nan, False, "nan ± 0.002"),
    ],
)
def test_a_measurement_conforms_when_inside_its_limits(
    value: float, conforms: bool, shown: str
) -> None:
    estimate = Estimate(name="x", value=value, standard_uncertainty=0.001, unit="N·m")
    outcome = judge(estimate, SPEC)
    measurement = Measurement(protocol="p", spec=SPEC, estimate=estimate, outcome=outcome)
    assert measurement.conforms is conforms
    assert measurement.verdict().startswith(f"x = {shown} N·m → {outcome.value}")
    assert "limits [0.9, 1.1]" in measurement.verdict()


def test_earlier_results_are_looked_up_by_name(tmp_path: Path) -> None:
    from hil.calibration import CalibrationRun
    from hil.profile import load_profile

    bias = MethodBiasMap(source="test", sha256="", entries={"inertia_kg_m2": MethodBias(
        name="inertia_kg_m2", relative=True, bias=0.01, scatter=0.005, units=10)})
    run = CalibrationRun(profile=load_profile(), unit_serial="X", out_dir=tmp_path,
                         drive_kind="sim", method_bias=bias)
    assert run.result("inertia_kg_m2") is None
    inertia = Estimate(name="inertia_kg_m2", value=0.0036, standard_uncertainty=1e-5,
                       unit="kg·m²")
    run.record("inertia_friction", inertia)
    found = run.result("inertia_kg_m2")
    assert found is not None
    assert found.value == pytest.approx(0.0036 / 1.01)  # as recorded: bias corrected
    assert found.standard_uncertainty > 1e-5  # and the method's scatter added
    assert run.results("inertia_kg_m2", "coulomb_nm") is None
    assert run.results("inertia_kg_m2") == (found,)


def test_a_result_proportional_to_another_takes_its_method_terms(tmp_path: Path) -> None:
    """f_res over the bandwidth carries f_res's relative bias and scatter, not its
    validation (that was measured on f_res, not on the ratio)."""
    from hil.calibration import CalibrationRun

    f_r = MethodBias(name="resonance_frequency_hz", relative=True, bias=0.004, scatter=0.001,
                     units=100, validated_coverage=0.96, validated_units=50)
    bias = MethodBiasMap(source="test", sha256="", entries={f_r.name: f_r})
    run = CalibrationRun(profile=load_profile(builtin_profile_path("demo_gimbal_azimuth")),
                         unit_serial="X", out_dir=tmp_path, drive_kind="sim", method_bias=bias)
    ratio = Estimate(name="resonance_to_bandwidth_ratio", value=6.0,
                     standard_uncertainty=1e-4, unit="1")
    alone = run.record("resonance", ratio)
    assert alone.estimate.value == 6.0
    assert alone.estimate.standard_uncertainty == 1e-4
    borrowed = run.record("resonance", ratio, method_of="resonance_frequency_hz")
    assert borrowed.estimate.value == pytest.approx(6.0 / 1.004)
    assert borrowed.estimate.standard_uncertainty == pytest.approx(
        math.hypot(1e-4, 0.001 * 6.0 / 1.004))
    assert borrowed.validation is None


def test_an_excitation_run_twice_keeps_both_recordings(tmp_path: Path) -> None:
    """Raw data is never overwritten within a run (the azimuth's sines at each elevation)."""
    import numpy as np

    from hil.calibration import CalibrationRun
    from hil.drives.sim import SimDrive
    from hil.motion import Excitation, Mode

    profile = load_profile()
    assert profile.plant is not None
    run = CalibrationRun(profile=profile, unit_serial="X", out_dir=tmp_path, drive_kind="sim")
    excitation = Excitation(name="hold", mode=Mode.VELOCITY, fs_hz=profile.sample_rate_hz,
                            command=np.zeros(40))
    with SimDrive(profile.plant, limits=profile.limits, fs_hz=profile.sample_rate_hz,
                  seed=0) as drive:
        drive.enable()
        run.run(drive, excitation, protocol="p")
        run.run(drive, excitation, protocol="p")
    paths = [raw.path for raw in run.raw_files]
    assert len(set(paths)) == 2
    assert all(path.is_file() for path in paths)


def test_a_method_line_holds_for_the_path_and_variant_it_was_measured_on() -> None:
    """The shipped map's J line assumes cogging and K_t ripple were taken out of the sines;
    without them its own (wider) line applies; a streamed τ gets its path's line and the
    simulator's line nowhere else."""
    from hil.measurement import WITHOUT_POSITION_TORQUE

    shipped = load_method_bias(axis="elevation")
    taken_out = shipped.line("inertia_kg_m2")
    without = shipped.line("inertia_kg_m2", variant=WITHOUT_POSITION_TORQUE)
    assert taken_out is not None
    assert without is not None
    assert without.scatter > 10 * taken_out.scatter  # the ripple's share of J's error
    assert without.variant == WITHOUT_POSITION_TORQUE
    streamed = "one row per 4 control periods, torque mean"
    tau = shipped.line("current_loop_time_constant_ms", path=streamed)
    assert tau is not None
    assert tau.acquisition == streamed
    assert shipped.line("inertia_kg_m2", path=streamed) is None
    assert shipped.line("current_loop_time_constant_ms", path="one row per 2 control "
                        "periods, torque mean") is None
