"""The method-bias map (``fixtures/method_bias.toml``) a population's results show, and its
validation on a second population.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats
from scipy.optimize import brentq

from hil.characterise.draw import Unit
from hil.characterise.run import Row
from hil.characterise.summary import FloatArray, Summary, by_result, errors_of, verdict
from hil.profile import load_profile
from hil.suite.catalogue import PROTOCOL_OF

BoolArray = NDArray[np.bool_]

HEADER = """\
# Each method's error over a simulated population of units, per axis, written by
# gimbal-hil characterise --write-map (see benchmarks/RESULTS.md). A calibration corrects
# the mean error (bias) and states the unit-to-unit scatter beyond Type A as a named Type B
# line of its budget. `--method-bias off` calibrates without it.
# validated_coverage / validated_units: how often the certificate's ±U held the truth on a
# second population not used for these figures (--validate-map); note: what keeps a
# result's coverage from 95 %, where that was traced; second_simulator: how ±U held over a
# second simulator's drawn choices (benchmarks/bench_variant_methods.py --write-notes).
# covariate: where the population's error follows a result measured before this one, the
# line a calibration applies at the unit's own value x of it: mean error
# bias + slope·(x − center), its scatter about that line, for x in [low, high] (else the
# population-wide line above). All are printed on the certificate.
"""


#: a unit this many of its total u from the line is a gross error of the method, not scatter
GROSS_Z = 6.0
#: at most this share of a population is set aside so (more is the method's scatter)
GROSS_SHARE = 0.02
#: a covariate's slope is taken as real at this family-wise level over every result and
#: covariate one map looks at: a population whose errors follow none shows one this often
COVARIATE_ALPHA = 0.05

#: (axis, result) → the results measured before it (by an earlier protocol of its profile)
Earlier = Mapping[tuple[str, str], Collection[str]]


def bias_map(rows: Iterable[Row], *, population: str,
             earlier: Earlier | None = None) -> dict[str, Any]:
    """The method-bias map (``fixtures/method_bias.toml``) the rows show, per axis.

    Per result, with errors ``e`` relative to the truth when every truth is positive (else
    absolute) and the stated (Type A) ``u``: the scatter ``s`` beyond what ``u`` covers is
    the maximum-likelihood one, ``mean((e − b)²/(u² + s²)) = 1`` (zero when the stated
    ``u`` already covers the errors), the bias ``b`` the mean of ``e`` weighted by
    ``1/(u² + s²)``; the bias's own standard error is added to ``s``. Units whose ``u``
    differs a lot (an ill-determined cable loop) then count by their own ``u``, which a
    moment estimate ``var(e) − mean(u²)`` would not do. A unit more than ``GROSS_Z`` total
    u from the line is a gross error and is left out of the fit, if such units are at most
    ``GROSS_SHARE`` of the population (``gross_errors`` counts them): one unit's K_t 30 u off
    made every other unit's line 5 × wider; they still count in the validation. Computed
    on results calibrated with ``--method-bias off``.

    With ``earlier`` (:func:`earlier_results`), each result's error is also regressed on
    each result its units measured before it (:func:`conditioned_line`), the covariate's
    values corrected by its own line as a calibration records them. The steepest slope, in
    units of its standard error, is kept as the result's ``covariate`` table when it
    passes the family-wise level :data:`COVARIATE_ALPHA` over every result and covariate
    looked at (Šidák): a population whose errors follow nothing gains a covariate in about
    one map of twenty.
    """
    groups = by_result(rows)
    results: dict[str, dict[str, Any]] = {}
    kept: dict[tuple[str, str], BoolArray] = {}
    for (axis, name), group in groups.items():
        relative, errors, u = errors_of(group)
        bias, scatter, weight, kept[(axis, name)] = _fitted(errors, u)
        entry = {
            "scale": "relative" if relative else "absolute",
            "bias": bias,
            "scatter": math.hypot(scatter, 1 / math.sqrt(weight)),
            "units": len(group),
        }
        gross_errors = int(np.sum(~kept[(axis, name)]))
        if gross_errors:
            entry["gross_errors"] = gross_errors
        results.setdefault(axis, {})[name] = entry
    candidates = _covariates(groups, results, earlier or {})
    cells = sum(len(found) for found in candidates.values())
    level = 1 - (1 - COVARIATE_ALPHA) ** (1 / max(cells, 1))  # each slope's (Šidák)
    for (axis, name), found in candidates.items():
        _, errors, u = errors_of(groups[(axis, name)])
        mask = kept[(axis, name)]
        lines = {covariate: conditioned_line(errors[mask], u[mask], x[mask])
                 for covariate, x in found.items()}
        covariate, line = max(lines.items(), key=lambda item: abs(item[1]["t"]))
        if 2 * stats.t.sf(abs(line.pop("t")), int(mask.sum()) - 2) < level:
            results[axis][name]["covariate"] = {"name": covariate, **line}
    return {"population": population, "results": results}


def earlier_results(units: Sequence[Unit]) -> dict[tuple[str, str], frozenset[str]]:
    """Per (axis, result): the results its profile measures in an earlier protocol (what a
    calibration of the unit knows when it records the result), from one unit of each axis
    (the units of one axis share their protocols and order)."""
    found: dict[tuple[str, str], frozenset[str]] = {}
    for unit in {u.axis: u for u in units}.values():
        profile = load_profile(unit.profile_path)
        order = {protocol: i for i, protocol in enumerate(profile.protocols)}
        position = {name: order.get(PROTOCOL_OF.get(name, ""), -1)
                    for name in profile.measurements}
        for name, at in position.items():
            found[(unit.axis, name)] = frozenset(
                other for other, before in position.items() if 0 <= before < at)
    return found


def _covariates(groups: Mapping[tuple[str, str], Sequence[Row]],
                results: Mapping[str, Mapping[str, Mapping[str, Any]]], earlier: Earlier,
                ) -> dict[tuple[str, str], dict[str, FloatArray]]:
    """Per result: each earlier result that every one of its units measured, in the
    units' order, corrected by that result's own line (as a calibration records it)."""
    measured: dict[tuple[str, str], dict[str, float]] = {}
    for (axis, name), group in groups.items():
        entry = results[axis][name]
        for row in group:
            measured.setdefault((row.unit, axis), {})[name] = (
                row.value / (1 + entry["bias"]) if entry["scale"] == "relative"
                else row.value - entry["bias"])
    found: dict[tuple[str, str], dict[str, FloatArray]] = {}
    for (axis, name), group in groups.items():
        units = [measured[(row.unit, axis)] for row in group]
        for covariate in sorted(earlier.get((axis, name), ())):
            if all(covariate in unit for unit in units):
                x = np.array([unit[covariate] for unit in units])
                if np.ptp(x) > 0:
                    found.setdefault((axis, name), {})[covariate] = x
    return found


def conditioned_line(errors: FloatArray, u: FloatArray, x: FloatArray) -> dict[str, float]:
    """The method line of :func:`bias_map` with its mean following ``x``:
    ``e = bias + slope·(x − center)`` weighted by ``1/(u² + s²)``, ``s`` the scatter beyond
    ``u`` about it (the same likelihood equation), ``center`` the weighted mean of ``x``
    (bias and slope then uncorrelated). Returns the keys of a map's ``covariate`` table
    (its scatter with the bias's standard error added) and ``t``, the slope over its
    standard error."""
    scatter = 0.0
    for _ in range(20):
        weights = 1 / (u**2 + scatter**2)
        center = float(np.sum(weights * x) / np.sum(weights))
        design = np.column_stack([np.ones_like(x), x - center])
        covariance = np.linalg.inv(design.T @ (weights[:, None] * design))
        coefficients = covariance @ (design.T @ (weights * errors))
        scatter = _excess_scatter(errors - design @ coefficients, u)
    bias_u, slope_u = np.sqrt(np.diag(covariance))
    return {"center": center, "low": float(np.min(x)), "high": float(np.max(x)),
            "bias": float(coefficients[0]), "slope": float(coefficients[1]),
            "slope_uncertainty": float(slope_u),
            "scatter": math.hypot(scatter, float(bias_u)),
            "t": float(coefficients[1] / slope_u)}


def fitted_line(errors: FloatArray, u: FloatArray) -> tuple[float, float, int]:
    """One result's method line from its units' ``errors`` and stated (Type A) ``u``
    (:func:`bias_map`): the bias, the scatter beyond ``u`` with the bias's own standard
    error added, and how many units were left out as gross errors."""
    bias, scatter, weight, kept = _fitted(errors, u)
    return bias, math.hypot(scatter, 1 / math.sqrt(weight)), int(np.sum(~kept))


def _fitted(errors: FloatArray, u: FloatArray) -> tuple[float, float, float, BoolArray]:
    """:func:`_line` of the units that are not gross errors, and which units those are."""
    kept = np.ones(len(errors), dtype=bool)
    bias, scatter, weight = _line(errors, u)
    for _ in range(5):
        gross = np.abs(errors - bias) > GROSS_Z * np.sqrt(u**2 + scatter**2)
        if gross.sum() > GROSS_SHARE * len(errors):
            kept[:] = True
            bias, scatter, weight = _line(errors, u)
            break
        if np.array_equal(~gross, kept):
            break
        kept = ~gross
        bias, scatter, weight = _line(errors[kept], u[kept])
    return bias, scatter, weight, kept


def _line(errors: FloatArray, u: FloatArray) -> tuple[float, float, float]:
    """Bias, excess scatter and the sum of weights of ``errors`` (:func:`bias_map`)."""
    bias, scatter = float(np.mean(errors)), 0.0
    for _ in range(20):
        scatter = _excess_scatter(errors - bias, u)
        weights = 1 / (u**2 + scatter**2)
        bias = float(np.sum(weights * errors) / np.sum(weights))
    return bias, scatter, float(np.sum(weights))


def with_validation(document: Mapping[str, Any], summaries: Iterable[Summary],
                    per_variant: Mapping[str, Iterable[Summary]] | None = None
                    ) -> dict[str, Any]:
    """The map ``document`` with each result's coverage on this (out-of-sample)
    population: ``validated_coverage`` and ``validated_units``; where a drawn variant of
    the simulator misses the goal on its own, its coverage per variant as the ``note`` the
    certificate prints; where none misses now, an earlier population's figure is dropped
    (other notes are kept)."""
    results = {axis: {name: dict(entry) for name, entry in table.items()}
               for axis, table in document["results"].items()}
    for s in summaries:
        entry = results.get(s.axis, {}).get(s.parameter)
        if entry is not None:
            entry["validated_coverage"] = round(s.coverage, 4)
            entry["validated_units"] = s.n
    by_result: dict[tuple[str, str], list[tuple[str, Summary]]] = {}
    for variant, group in (per_variant or {}).items():
        for s in group:
            by_result.setdefault((s.axis, s.parameter), []).append((variant, s))
    for (axis, name), found in by_result.items():
        entry = results.get(axis, {}).get(name)
        if entry is None:
            continue
        old = str(entry.pop("note", "")).split(" | by variant: ")[0]
        old = "" if old.startswith("by variant: ") else old
        if any(verdict(s) == "MISSED" for _, s in found):
            said = "; ".join(f"{v} {100 * s.coverage:.0f} % of {s.n}" for v, s in found)
            old = f"{old} | by variant: {said}" if old else f"by variant: {said}"
        if old:
            entry["note"] = old
    return {**document, "results": results}


def _excess_scatter(errors: FloatArray, u: FloatArray) -> float:
    """``s ≥ 0`` with ``mean(e²/(u² + s²)) = 1``."""

    def excess(s: float) -> float:
        return float(np.mean(errors**2 / (u**2 + s**2))) - 1.0

    if excess(0.0) <= 0:
        return 0.0
    high = float(np.sqrt(np.mean(errors**2))) + 1e-300
    return float(brentq(excess, 0.0, high))
