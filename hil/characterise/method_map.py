"""The method-bias map (``fixtures/method_bias.toml``) a population's results show, and its
validation on a second population.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
from scipy.optimize import brentq

from hil.characterise.run import Row
from hil.characterise.summary import FloatArray, Summary, by_result, errors_of, verdict

HEADER = """\
# Each method's error over a simulated population of units, per axis, written by
# gimbal-hil characterise --write-map (see benchmarks/RESULTS.md). A calibration corrects
# the mean error (bias) and states the unit-to-unit scatter beyond Type A as a named Type B
# line of its budget. `--method-bias off` calibrates without it.
# validated_coverage / validated_units: how often the certificate's ±U held the truth on a
# second population not used for these figures (--validate-map); note: what keeps a
# result's coverage from 95 %, where that was traced; second_simulator: how ±U held over a
# second simulator's drawn choices (benchmarks/bench_variant_methods.py --write-notes).
# All are printed on the certificate.
"""


#: a unit this many of its total u from the line is a gross error of the method, not scatter
GROSS_Z = 6.0
#: at most this share of a population is set aside so (more is the method's scatter)
GROSS_SHARE = 0.02


def bias_map(rows: Iterable[Row], *, population: str) -> dict[str, Any]:
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
    """
    results: dict[str, dict[str, Any]] = {}
    for (axis, name), group in by_result(rows).items():
        relative, errors, u = errors_of(group)
        bias, scatter, gross_errors = fitted_line(errors, u)
        entry = {
            "scale": "relative" if relative else "absolute",
            "bias": bias,
            "scatter": scatter,
            "units": len(group),
        }
        if gross_errors:
            entry["gross_errors"] = gross_errors
        results.setdefault(axis, {})[name] = entry
    return {"population": population, "results": results}


def fitted_line(errors: FloatArray, u: FloatArray) -> tuple[float, float, int]:
    """One result's method line from its units' ``errors`` and stated (Type A) ``u``
    (:func:`bias_map`): the bias, the scatter beyond ``u`` with the bias's own standard
    error added, and how many units were left out as gross errors."""
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
    return bias, math.hypot(scatter, 1 / math.sqrt(weight)), int(np.sum(~kept))


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
    certificate prints (other notes are kept)."""
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
        if entry is None or all(verdict(s) != "MISSED" for _, s in found):
            continue
        said = "; ".join(f"{v} {100 * s.coverage:.0f} % of {s.n}" for v, s in found)
        note = f"by variant: {said}"
        old = str(entry.get("note", "")).split(" | by variant: ")[0]
        old = "" if old.startswith("by variant: ") else old
        entry["note"] = f"{old} | {note}" if old else note
    return {**document, "results": results}


def _excess_scatter(errors: FloatArray, u: FloatArray) -> float:
    """``s ≥ 0`` with ``mean(e²/(u² + s²)) = 1``."""

    def excess(s: float) -> float:
        return float(np.mean(errors**2 / (u**2 + s**2))) - 1.0

    if excess(0.0) <= 0:
        return 0.0
    high = float(np.sqrt(np.mean(errors**2))) + 1e-300
    return float(brentq(excess, 0.0, high))
