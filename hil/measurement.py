"""Declared measurements judged against their limits: PASS / MARGINAL / FAIL.

A tolerance miss is an outcome, not an exception.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from enum import StrEnum
from pathlib import Path

from hil.config import ConfigTable, builtin_fixture, read_results_by_axis, read_toml
from hil.gum import format_result
from hil.identify.estimate import Component, Estimate
from hil.profile import MeasurementSpec
from hil.recording import EVERY_CONTROL_PERIOD

METHOD_BIAS_FILE = "method_bias.toml"
#: method lines of acquisition paths other than the simulator's (over an emulator)
ACQUISITION_BIAS_FILE = "method_bias_acquisition.toml"
#: method lines of a protocol run without an input its shipped line assumes
VARIANT_BIAS_FILE = "method_bias_variants.toml"
#: the sine protocols' variant when no cogging and K_t ripple map could be taken out
WITHOUT_POSITION_TORQUE = "cogging and K_t ripple not taken out"

DECISION_RULE = (
    "Simple acceptance with the expanded uncertainty U (k≈2, ~95 %) stated (ILAC-G8:09/2019 "
    "4.2.1). PASS: value inside the limits, value ± U inside the limits and the value outside "
    "the marginal band next to either limit (a fraction of the distance from the nominal to "
    "that limit). MARGINAL: value inside the limits but within the "
    "marginal band or with a limit inside value ± U. FAIL: value outside the limits. A "
    "quantity that cannot be negative (a spread, a ripple) cannot cross a lower limit at or "
    "below zero: that limit has no marginal band and value − U below it is no risk. The unit "
    "conforms when every result is PASS or MARGINAL and every protocol ran to completion."
)


class Outcome(StrEnum):
    PASS = "PASS"
    MARGINAL = "MARGINAL"
    FAIL = "FAIL"
    ERROR = "ERROR"  # the protocol did not complete: no conformity statement possible
    INCOMPLETE = "INCOMPLETE"  # a required declared result was not measured: no statement


@dataclass(frozen=True, slots=True)
class Declared:
    """A protocol's declared measurement as a customer reads it (``protocols/test_*.py``).

    Attributes
    ----------
    name : str
        The code name, as the profile's ``[measurements.NAME]`` and the JSON have it.
    title : str
        What it is called on the certificate ("Moment of inertia").
    description : str
        One line: what it is and how it was measured.
    non_negative : bool
        A size by nature (amplitude, RMS, peak, time): with a lower limit at or below zero
        its limits read one-sided, ``≤ upper``.
    """

    name: str
    title: str
    description: str
    non_negative: bool = False


def declare(*measurements: Declared) -> dict[str, Declared]:
    """A protocol's declarations by code name (each name once)."""
    found = {m.name: m for m in measurements}
    if len(found) != len(measurements):
        raise ValueError("a measurement is declared twice")
    return found


@dataclass(frozen=True, slots=True, kw_only=True)
class Measurement:
    protocol: str
    spec: MeasurementSpec
    estimate: Estimate
    outcome: Outcome
    validation: dict[str, object] | None = None  # the method-bias map's out-of-sample check
    declared: Declared | None = None  # title and description (None: the code name stands)

    @property
    def conforms(self) -> bool:
        """PASS or MARGINAL: inside the limits."""
        return self.outcome in (Outcome.PASS, Outcome.MARGINAL)

    def verdict(self) -> str:
        """``name = value ± U unit → OUTCOME (limits [lo, hi])``, for logs and test reports."""
        e, spec = self.estimate, self.spec
        return (
            f"{spec.name} = {format_result(e.value, e.expanded_uncertainty, spec.unit)} → "
            f"{self.outcome.value} (limits [{spec.lower_limit:.6g}, {spec.upper_limit:.6g}])"
        )


def judge(estimate: Estimate, spec: MeasurementSpec, *, non_negative: bool = False) -> Outcome:
    """Apply :data:`DECISION_RULE` (``non_negative``: the quantity cannot be below zero)."""
    value, expanded = estimate.value, estimate.expanded_uncertainty
    if not math.isfinite(value) or not spec.lower_limit <= value <= spec.upper_limit:
        return Outcome.FAIL
    # a lower limit the quantity cannot cross (a spread's "≥ 0") is no risk at any U: a
    # spread of 0.5 ± 1 % was MARGINAL against [-0.001, 5] for its interval's impossible part
    lower_binds = not (non_negative and spec.lower_limit <= 0.0)
    # the marginal band is a fraction of the distance from the nominal to each limit, so a
    # one-sided quantity (nominal at its lower limit, smaller is better) has none below
    low_band = spec.marginal_fraction * max(spec.nominal - spec.lower_limit, 0.0)
    high_band = spec.marginal_fraction * max(spec.upper_limit - spec.nominal, 0.0)
    near_limit = (lower_binds and value < spec.lower_limit + low_band) or (
        value > spec.upper_limit - high_band)
    straddles = (lower_binds and value - expanded < spec.lower_limit) or (
        value + expanded > spec.upper_limit)
    return Outcome.MARGINAL if near_limit or straddles else Outcome.PASS


@dataclass(frozen=True, slots=True, kw_only=True)
class MethodCovariate:
    """A method's error that follows another result the unit measured before (issue 30:
    a line for this kind of unit, not only the population's average one): mean error
    ``bias + slope·(x − center)`` at the unit's measured ``x``, ``scatter`` about that line,
    fitted over the population's range ``[low, high]`` of ``x``
    (:func:`hil.characterise.method_map.bias_map`).

    Attributes
    ----------
    name : str
        The covariate, an earlier protocol's declared measurement.
    center, low, high : float
        Its mean and range over the population, in its own unit.
    bias : float
        Mean error at ``center`` (relative or absolute as the line it conditions).
    slope, slope_uncertainty : float
        Change of the mean error per unit of the covariate, and its standard error.
    scatter : float
        Scatter about the conditioned line beyond Type A, with its intercept's standard
        error.
    """

    name: str
    center: float
    low: float
    high: float
    bias: float
    slope: float
    slope_uncertainty: float
    scatter: float


@dataclass(frozen=True, slots=True, kw_only=True)
class MethodBias:
    """A method's error over a simulated population of units (``bench_coverage.py``).

    Attributes
    ----------
    name : str
        The declared measurement.
    relative : bool
        ``bias`` and ``scatter`` are fractions of the value (else in its unit).
    bias : float
        Mean error ``x − truth`` (relative: over the truth): corrected, not covered.
    scatter : float
        Standard deviation of the error from unit to unit beyond what Type A states, with
        the correction's own uncertainty: a Type B line of the budget.
    units : int
        Population size behind the figures.
    validated_coverage : float or None
        On a second population, not used for the figures: the fraction of units whose
        certificate's ``value ± U`` held the truth.
    validated_units : int or None
        Size of that population.
    note : str
        What keeps a result's validated coverage from 95 %, when something does.
    second_simulator : str
        How its ±U held over a second simulator's drawn choices (``plant_sim.variant``;
        ``benchmarks/bench_variant_methods.py --write-notes``), the choices that miss named.
    acquisition : str
        The acquisition path the population was recorded on.
    variant : str
        The method's variant it was measured for ("": as the main map assumes).
    gross_errors : int
        Units of the population left out of bias and scatter as gross errors (many of their
        total u from the line; ``hil.characterise.method_map.bias_map``).
    covariate : MethodCovariate or None
        The line conditioned on an earlier result, where the population showed its error
        following one (:meth:`at`).
    condition : str
        Where :meth:`at` placed this line (``""``: the population-wide line).
    """

    name: str
    relative: bool
    bias: float
    scatter: float
    units: int
    validated_coverage: float | None = None
    validated_units: int | None = None
    note: str = ""
    second_simulator: str = ""  # its validation over plant_sim.variant's drawn choices
    acquisition: str = EVERY_CONTROL_PERIOD  # the path its population was recorded on
    variant: str = ""  # the method run without an input the main map assumes
    gross_errors: int = 0  # units left out of the figures as gross errors
    covariate: MethodCovariate | None = None
    condition: str = ""

    def at(self, measured: Mapping[str, float]) -> MethodBias:
        """This line for a unit whose earlier results are ``measured`` (by name): the
        conditioned line at the unit's covariate, with the slope's uncertainty there, when
        the unit measured it inside the population's range; else the population-wide one."""
        line = self.covariate
        x = None if line is None else measured.get(line.name)
        if line is None or x is None or not line.low <= x <= line.high:
            return self
        offset = x - line.center
        return replace(self, bias=line.bias + line.slope * offset,
                       scatter=math.hypot(line.scatter, offset * line.slope_uncertainty),
                       condition=f"{line.name} {x:.4g}")

    def validation(self) -> dict[str, object] | None:
        """What the certificate states of the map's out-of-sample check, if made."""
        if self.validated_coverage is None:
            return None
        note = "; ".join(part for part in (self.note, self.second_simulator) if part)
        return {"coverage": self.validated_coverage, "units": self.validated_units,
                "note": note}


@dataclass(frozen=True, slots=True, kw_only=True)
class MethodBiasMap:
    """The method corrections a calibration applies, and the file they came from."""

    source: str
    sha256: str
    entries: Mapping[str, MethodBias]
    #: lines of other acquisition paths: path → result → line
    acquisition: Mapping[str, Mapping[str, MethodBias]] = field(default_factory=dict)
    #: lines of a method run without an input the main map assumes: variant → result → line
    variants: Mapping[str, Mapping[str, MethodBias]] = field(default_factory=dict)

    def line(self, name: str, *, path: str | None = None,
             variant: str | None = None) -> MethodBias | None:
        """``name``'s method line on the acquisition ``path`` its recording came over
        (``None``: the simulator's, :data:`EVERY_CONTROL_PERIOD`), for the method's
        ``variant`` (e.g. :data:`WITHOUT_POSITION_TORQUE`) when it ran as one. A line is
        valid on the path and variant it was measured on only: another gets its own or
        none."""
        if variant is not None and (path is None or path == EVERY_CONTROL_PERIOD):
            return self.variants.get(variant, {}).get(name)
        if path is None or path == EVERY_CONTROL_PERIOD:
            return self.entries.get(name)
        return self.acquisition.get(path, {}).get(name)


def load_method_bias(path: Path | None = None, *, axis: str = "") -> MethodBiasMap:
    """Read a method-bias map (default: the one shipped, ``fixtures/method_bias.toml``).

    Parameters
    ----------
    path : Path or None
        The map's file.
    axis : str
        The profile's ``[unit] axis``: the map holds one table of results per axis
        (``[results.elevation.NAME]``), since a method's error depends on the physics of
        the axis it measures. An axis the map lacks gets no corrections.

    Returns
    -------
    MethodBiasMap

    Raises
    ------
    ProfileError
        A missing, mistyped or unknown key in any table, naming file, table and key.
    """
    path = path or builtin_fixture(METHOD_BIAS_FILE)
    sha256, by_axis = read_results_by_axis(path, _method_bias)
    return MethodBiasMap(source=str(path), sha256=sha256, entries=by_axis.get(axis, {}),
                         acquisition=_keyed_lines(builtin_fixture(ACQUISITION_BIAS_FILE),
                                                  "acquisition", axis=axis),
                         variants=_keyed_lines(builtin_fixture(VARIANT_BIAS_FILE), "variant",
                                               axis=axis))


def acquisition_band(line: MethodBias, *, value: float, unit: str) -> Component:
    """A method line of another acquisition path as a budget line: not a correction, since
    the path's effect depends on the drive (the images of a 1 kHz target's interpolation
    pass its own velocity loop) and the line was measured on one emulator, but a
    rectangular band of half-width ``|bias| + 2·scatter`` around the value."""
    half = abs(line.bias) + 2 * line.scatter
    sign = "+" if line.bias >= 0 else "−"
    shown = f"{100 * half:.2g} %" if line.relative else f"{half:.2g}"
    return Component(
        source=f"method: this acquisition path ({line.acquisition}) moved it by "
               f"{sign}{100 * abs(line.bias) if line.relative else abs(line.bias):.2g}"
               f"{' %' if line.relative else ''} over {line.units} emulated units; "
               f"drive-dependent, not corrected: ±{shown} rectangular",
        kind="B", standard_uncertainty=half * (abs(value) if line.relative else 1.0)
        / math.sqrt(3), unit=unit)


def _keyed_lines(path: Path, key: str, *, axis: str) -> dict[str, dict[str, MethodBias]]:
    """The shipped lines of other acquisition paths (``key`` ``acquisition``:
    ``[acquisition."PATH".results.AXIS.NAME]``, benchmarks/bench_acquisition_path.py) or
    method variants (``variant``) for ``axis``, by path or variant."""
    document, _ = read_toml(path)
    root = ConfigTable.root(document, source=str(path))
    root.string("population")
    found = {}
    for label, table in root.tables(key).items():
        by_axis = {name: {result: _method_bias(result, entry)
                          for result, entry in results.tables_here().items()}
                   for name, results in table.tables("results").items()}
        table.done()
        found[label] = {
            name: (replace(line, acquisition=label,
                           note=line.note or "over the CANopen emulator, on this path")
                   if key == "acquisition" else replace(line, variant=label))
            for name, line in by_axis.get(axis, {}).items()}
    root.done()
    return found


def _method_bias(name: str, table: ConfigTable) -> MethodBias:
    bias = MethodBias(
        name=name,
        relative=table.choice("scale", ("relative", "absolute")) == "relative",
        bias=table.number("bias"),
        scatter=table.non_negative("scatter"),
        units=table.integer("units"),
        validated_coverage=(table.number("validated_coverage")
                            if "validated_coverage" in table else None),
        validated_units=(table.integer("validated_units")
                         if "validated_units" in table else None),
        note=table.string("note", ""),
        second_simulator=table.string("second_simulator", ""),
        gross_errors=table.integer("gross_errors") if "gross_errors" in table else 0,
        covariate=_method_covariate(table.table_at("covariate"))
        if "covariate" in table else None,
    )
    table.done()
    return bias


def _method_covariate(table: ConfigTable) -> MethodCovariate:
    covariate = MethodCovariate(
        name=table.string("name"), center=table.number("center"), low=table.number("low"),
        high=table.number("high"), bias=table.number("bias"), slope=table.number("slope"),
        slope_uncertainty=table.non_negative("slope_uncertainty"),
        scatter=table.non_negative("scatter"))
    if not covariate.low <= covariate.center <= covariate.high:
        raise table.error("center", f"must lie in [low, high], got {covariate.center!r} "
                                    f"outside [{covariate.low!r}, {covariate.high!r}]")
    table.done()
    return covariate


def with_method_terms(
    estimate: Estimate, spec: MeasurementSpec, bias: MethodBias | None
) -> Estimate:
    """Correct the method's known bias and add the budget lines the data cannot show.

    Parameters
    ----------
    estimate : Estimate
        As the protocol's analysis gives it.
    spec : MeasurementSpec
        Its declaration; ``allowance_rel`` adds a rectangular line for physics the
        simulator lacks.
    bias : MethodBias or None
        The method's error over a population, when measured: over simulated units on the
        simulator's path (:data:`EVERY_CONTROL_PERIOD`), corrected; over emulated units on
        another acquisition path, a band (:func:`acquisition_band`), not corrected.

    Returns
    -------
    Estimate
        Value corrected by the population's mean error; budget with the error's
        unit-to-unit scatter (or the path's band) and the allowance as named Type B lines.
    """
    value, added = estimate.value, []
    if bias is not None and bias.acquisition != EVERY_CONTROL_PERIOD:
        added.append(acquisition_band(bias, value=value, unit=estimate.unit))
    elif bias is not None:
        value = value / (1 + bias.bias) if bias.relative else value - bias.bias
        scatter = bias.scatter * abs(value) if bias.relative else bias.scatter
        sign = "+" if bias.bias >= 0 else "−"
        size = f"{100 * abs(bias.bias):.2g} %" if bias.relative else f"{abs(bias.bias):.2g}"
        added.append(Component(
            source=f"method: error over {bias.units} simulated units beyond Type A"
                   f"{', ' + bias.variant if bias.variant else ''}"
                   f"{', at ' + bias.condition if bias.condition else ''} "
                   f"(mean {sign}{size} corrected)",
            kind="B", standard_uncertainty=scatter, unit=estimate.unit))
    if spec.allowance_rel:
        added.append(Component(
            source="allowance for physics the simulator lacks (profile allowance_pct, "
                   "rectangular)",
            kind="B", standard_uncertainty=spec.allowance_rel * abs(value) / math.sqrt(3),
            unit=estimate.unit))
    return estimate.with_components(*added, value=value)
