"""The JSON report of ``gimbal-hil diagnose`` (layout documented in ``docs/diagnose.md``)."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hil.diagnose import alias, constant, interpret, intervals, lag, ripple, unexplained
from hil.diagnose.model import Fit, fit_percent, solve
from hil.diagnose.profile_out import extended_firmware, extended_plant
from hil.diagnose.select import DECISION_RULE, Candidate

if TYPE_CHECKING:
    from hil.diagnose.core import Diagnosis

FORMAT = "gimbal-hil-diagnose/1"


def model_parameters(fit: Fit, lag_std_s: float = math.nan) -> dict[str, Any]:
    """Every named parameter of a fitted model (base and each effect).

    Parameters
    ----------
    fit : Fit
    lag_std_s : float
        Standard deviation of the current-loop time constant, s, when known.

    Returns
    -------
    dict of str to Any
        The base names (``inertia_kg_m2``, ...), then ``"{effect}.{name}"`` for each
        effect's parameters (see :func:`hil.diagnose.interpret.effect_parameters`).
    """
    out: dict[str, Any] = {n: e.value for n, e in interpret.base_parameters(fit).items()}
    for effect in fit.model.effects:
        if effect == "base":
            continue
        named = interpret.effect_parameters(effect, fit, lag_std_s=lag_std_s)["parameters"]
        out.update({f"{effect}.{k}": v for k, v in named.items()})
    return out


def _gain(candidate: Candidate) -> dict[str, Any]:
    g = candidate.gain
    return {
        "rms_before_nm": g.rms_before_nm,
        "rms_after_nm": g.rms_after_nm,
        "fit_before_pct": g.fit_before_pct,
        "fit_after_pct": g.fit_after_pct,
        "delta_bic": g.delta_bic,
        "rms_reduction": g.rms_reduction,
        "wald_statistic": g.wald_statistic,
        "wald_threshold_99": g.wald_threshold,
        "physically_plausible": g.plausible,
        "significant": g.significant,
    }


def _cause(rank: int, candidate: Candidate, diagnosis: Diagnosis,
           aliases: tuple[alias.Alias, ...] = ()) -> dict[str, Any]:
    # the held-out data judged the model; once judged, every usable row estimates it
    signals, rows = diagnosis.estimation_rows
    # every cause's parameters from the model with all the causes: the model of the causes
    # ranked up to this one leaves the others' torque to it (a first-ranked cogging carried
    # the gravity it was searched beside, 0.011 for 0.0069 N·m)
    joint = diagnosis.selection.final
    fitted = joint
    lag_std_s = candidate.lag_std_s
    if candidate.effect == "current_lag":  # (τ, δ) searched again without each group
        # on its ranked model: beside every cause, a Stribeck's misfit pulls τ lower still
        model, lag_std_s = lag.jackknife_lag(diagnosis.designer, signals, rows,
                                             candidate.fit.model, intervals.JACKKNIFE_GROUPS)
        fitted = replace(candidate.fit, model=model)
    if candidate.effect == "kt_ripple":  # stage one: the sweeping rows, band-limited
        model = diagnosis.final.model  # its weight the joint model's load (effects.reweighted)
        matrix, target, kept = ripple.estimation_data(diagnosis.designer, model, signals, rows)
        fit = intervals.jackknife_solve(
            solve(model, matrix, target, n_effective=float(kept.size)), matrix, target)
    else:
        fit = intervals.jackknife_fit(diagnosis.designer, fitted, signals, rows)
    named = interpret.effect_parameters(candidate.effect, fit, lag_std_s=lag_std_s,
                                        coverage=intervals.JACKKNIFE_COVERAGE,
                                        coverage99=intervals.JACKKNIFE_COVERAGE_99)
    if candidate.effect == "stribeck":
        profile = intervals.stribeck_profile(diagnosis.designer, fit, signals, rows)
        if profile is not None:
            for name in ("static_torque_nm", "stribeck_velocity_rad_s"):
                # the profile likelihood's interval: T_s and v_s trade off against each other
                named["uncertainty"][name]["ci95"] = profile[name]
                named["uncertainty"][name]["ci99"] = None
            named["separable"] = profile["separable"]
            if "excitation" in profile:
                named["note"] = profile["excitation"]
    confounded = alias.declared(diagnosis, aliases, candidate.effect)
    if confounded:  # the interval covers every split with the effect it cannot be told from
        entry = named["uncertainty"][confounded["key"]]
        own = entry["ci95"] or [-math.inf, math.inf]
        entry["ci95"] = [min(own[0], confounded["ci95"][0]), max(own[1], confounded["ci95"][1])]
        entry["ci99"] = None
        named["separable"] = False
        named["not_separable_from"] = confounded["not_separable_from"]
        named["note"] = "; ".join(n for n in (named.get("note"), confounded["note"]) if n)
    out: dict[str, Any] = {
        "rank": rank,
        "name": candidate.effect,
        "parameters": named["parameters"],
        "uncertainty": named["uncertainty"],
        "gain": _gain(candidate),
        "model_parameters": model_parameters(candidate.fit, candidate.lag_std_s),
    }
    if "separable" in named:
        out["separable"] = named["separable"]
    if "not_separable_from" in named:
        out["not_separable_from"] = named["not_separable_from"]
    if "note" in named:
        out["note"] = named["note"]
    # a constant and a Coulomb difference between the directions: one column (constant.py)
    coverage = (intervals.JACKKNIFE_COVERAGE, intervals.JACKKNIFE_COVERAGE_99)
    if candidate.effect == "offset":
        constant.describe_offset(out, fit, *coverage)
    elif candidate.effect == "asymmetric_friction":
        part = constant.offset_part(out, candidate, fit, diagnosis, _gain, *coverage)
        if part is not None:
            out["offset_part"] = part
    return out


def _causes(diagnosis: Diagnosis, aliases: tuple[alias.Alias, ...]) -> list[dict[str, Any]]:
    """Every cause's entry, ranked; an asymmetric friction's constant follows it as its
    own ``offset`` entry (:func:`hil.diagnose.constant.offset_part`)."""
    out: list[dict[str, Any]] = []
    for candidate in diagnosis.causes:
        entry = _cause(len(out) + 1, candidate, diagnosis, aliases)
        part = entry.pop("offset_part", None)
        out.append(entry)
        if part is not None:
            out.append({**part, "rank": len(out) + 1})
    return out


def report(diagnosis: Diagnosis) -> dict[str, Any]:
    """The report as plain JSON-able data (NaN and infinities become ``null``).

    Parameters
    ----------
    diagnosis : Diagnosis

    Returns
    -------
    dict of str to Any
        Layout in ``docs/diagnose.md`` (format :data:`FORMAT`).

    Raises
    ------
    ProfileError
        The extended model is not a valid plant.
    """
    from hil.diagnose.core import base_parameters, summary_metrics

    signals = diagnosis.signals
    base_metrics = summary_metrics(diagnosis, diagnosis.base)
    final_metrics = summary_metrics(diagnosis, diagnosis.final)
    tests = dict(diagnosis.residual["tests"])
    tests["spectrum_peaks_hz"] = diagnosis.residual["spectrum"]["peaks_hz"]
    aliases = alias.find(diagnosis)
    rounds = [
        [{"name": c.effect, "gain": _gain(c)} for c in candidates]
        for candidates in diagnosis.selection.rounds
    ]
    data = {
        "format": FORMAT,
        "source": diagnosis.recording.source,
        "validate": diagnosis.heldout.signals.source
        if diagnosis.heldout.signals is not signals else None,
        "axis_kind": signals.axis_kind,
        "units": interpret.units(signals.axis_kind),
        "analysis": {
            "sample_rate_hz": signals.fs_hz,
            "cutoff_hz": signals.cutoff_hz,
            "decimation": signals.decimation,
            "resampled": signals.resampled,
            "split": diagnosis.split,
            "train_rows": int(diagnosis.train.rows.size),
            "heldout_rows": int(diagnosis.heldout.rows.size),
            "effort": "effort low-passed zero-phase at cutoff_hz, like every regressor",
        },
        "base": {
            **base_parameters(diagnosis),
            "rms_nm": base_metrics["heldout_rms_nm"],
            "fit_pct": base_metrics["heldout_fit_pct"],
            "metrics": base_metrics,
        },
        "residual_tests": tests,
        "residual": {
            "against_position": diagnosis.residual["against_position"],
            "against_velocity": diagnosis.residual["against_velocity"],
        },
        "data_issues": [issue.as_dict() for issue in diagnosis.issues],
        "decision_rule": DECISION_RULE,
        "causes": _causes(diagnosis, aliases),
        "candidates_by_round": rounds,
        **final_structure(diagnosis),
        "extended_model": {
            "effects": diagnosis.cause_names,
            "metrics": final_metrics,
            "parameters": model_parameters(diagnosis.final),
            "plant": extended_plant(diagnosis),
            "firmware": extended_firmware(diagnosis),
        },
    }
    result = _clean(data)
    assert isinstance(result, dict)
    return result


def final_structure(diagnosis: Diagnosis) -> dict[str, Any]:
    """Structure the final model leaves in the held-out residual.

    Parameters
    ----------
    diagnosis : Diagnosis

    Returns
    -------
    dict of str to Any
        ``unexplained`` (bool) and ``unexplained_structure``: where it lies and the tests
        (:func:`hil.diagnose.unexplained.judge`), with the Ljung–Box test of the same
        residual (reported, not deciding).
    """
    from hil.diagnose.residual import residual_tests

    signals, rows = diagnosis.heldout.signals, diagnosis.heldout.rows
    measured, predicted = diagnosis.heldout_prediction(diagnosis.final)
    residual = measured - predicted
    judged = unexplained.judge(
        position=signals.position[rows], velocity=signals.velocity[rows], residual=residual,
        independence=min(1.0, signals.independence * signals.decimation),
        rotary=signals.axis_kind == "rotary",
        travel=unexplained.travel_since_reversal(signals.position, signals.velocity)[rows])
    poor_fit = unexplained.misfit(fit_percent(measured, predicted))
    judged["misfit"] = {"min_fit_pct": unexplained.MIN_FIT_PCT, "found": poor_fit is not None}
    if poor_fit is not None:
        judged["where"].append(poor_fit)
        judged["unexplained"] = True
    whiteness = residual_tests(residual, signals.velocity[rows], input_name="velocity")
    judged["ljung_box"] = whiteness["ljung_box"]
    judged["cross_correlation_independent"] = whiteness["cross_correlation"]["independent"]
    return {"unexplained": judged.pop("unexplained"), "unexplained_structure": judged}


def _clean(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if hasattr(value, "item"):  # numpy scalar
        return _clean(value.item())
    return value


def write_json(diagnosis: Diagnosis, path: str | Path) -> dict[str, Any]:
    """Write :func:`report` as UTF-8 JSON to ``path`` (its directory created when missing).

    Parameters
    ----------
    diagnosis : Diagnosis
    path : str or Path

    Returns
    -------
    dict of str to Any
        The report written.

    Raises
    ------
    ProfileError
        The extended model is not a valid plant.
    """
    data = report(diagnosis)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    return data
