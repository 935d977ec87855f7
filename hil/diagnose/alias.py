"""Named causes the recording cannot tell from a screened effect that was not named.

Over a gimbal's ±0.6 rad sweep a spring ``k·θ`` and gravity's ``m·g·e·cos(θ + φ)`` differ
only by the cosine's curvature and the sine's cubic term, and gravity's constant part is an
offset. When the data hold some of both, the selection names one, and that one's
parameters carry the other. Whether that happened is a property of the data, computed here
for every named cause ``C`` and every effect ``E`` significant in a screening round but not
named:

1. *evidence*: ``E`` added to the named causes lowers the training BIC by at least
   :data:`EVIDENCE_BIC` (the decision rule's −10, "very strong"), or its key coefficients
   there are significant (the decision rule's Wald test at 99 %: with one parameter the
   BIC's penalty of ``ln n`` ≈ 9 hides a coefficient at 4 σ) — the data hold something of
   ``E``'s shape that the named causes do not (it was not named because it failed the
   held-out gain, the Wald test or the halves test beside them) — or ``E`` in place of
   ``C`` raises it by less than that: the data do not choose ``C`` over ``E``;
2. *confounding*: with ``E``'s columns in the model, the variance of ``C``'s key parameter
   grows by at least :data:`INFLATION` (its variance inflation factor: ``C``'s columns are
   ≥ 90 % explained by ``E``'s given the rest).

Then ``C`` is reported ``"separable": false``: its 95 % interval becomes the union of its
own and the joint fit's, and the joint fit's interval of ``E``'s key parameter is reported
beside it (``not_separable_from``), with the excitation that would separate them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from hil.diagnose import interpret, intervals
from hil.diagnose.data_issues import encoder_counts
from hil.diagnose.select import (
    DELTA_BIC_MAX,
    KEY_LABELS,
    joint_model,
    researched_model,
    screened_effects,
    wald,
)

if TYPE_CHECKING:
    from hil.diagnose.core import Diagnosis

#: BIC drop ``E`` must bring beside the named causes: the decision rule's "very strong" evidence.
EVIDENCE_BIC = DELTA_BIC_MAX
#: Variance inflation of ``C``'s key parameter by ``E``'s columns that makes them confounded
#: (a multiple correlation of 0.95).
INFLATION = 10.0
#: The parameter the confounding is judged on, per effect (the reported key parameter; the
#: load inertia for a resonance, whose frequency has no interval). The current-loop lag has
#: no linear coefficient and is not judged.
KEY_PARAMETER = {
    "offset": "offset_nm",
    "asymmetric_friction": "viscous_neg",
    "stribeck": "static_torque_nm",
    "cogging": "amplitude_nm",
    "kt_ripple": "relative_amplitude",
    "gravity": "mge_nm",
    "cable_spring": "stiffness_nm_per_rad",
    "two_mass": "load_inertia_kg_m2",
}
POSITION_EFFECTS = frozenset({"offset", "gravity", "cable_spring"})


@dataclass(frozen=True, slots=True, kw_only=True)
class Alias:
    """A named cause confounded with an effect that was not named.

    Attributes
    ----------
    cause, other : str
        The named cause ``C`` and the screened effect ``E``.
    delta_bic : float
        Training BIC of the named causes with ``E`` minus without.
    inflation : float
        Variance inflation of ``C``'s key parameter by ``E``'s columns.
    instead_delta_bic : float
        Training BIC with ``E`` in place of ``C`` minus that of the named causes (NaN when
        ``E`` beside them was evidence enough).
    wald_statistic, wald_threshold : float
        Wald statistic of ``E``'s key coefficients beside the named causes, and its 99 %
        χ² threshold.
    """

    cause: str
    other: str
    delta_bic: float
    inflation: float
    instead_delta_bic: float = math.nan
    wald_statistic: float = math.nan
    wald_threshold: float = math.nan


def _key_std(effect: str, fit: Any) -> float:
    named = interpret.effect_parameters(effect, fit, method=False)
    entry = named["uncertainty"].get(KEY_PARAMETER[effect])
    return math.nan if entry is None or entry["std"] is None else float(entry["std"])


def find(diagnosis: Diagnosis) -> tuple[Alias, ...]:
    """Every (named cause, screened effect) pair the recording cannot separate.

    Parameters
    ----------
    diagnosis : Diagnosis

    Returns
    -------
    tuple of Alias
        Judged on the training rows with the fits' own covariance (see the module
        docstring for the two conditions).
    """
    named = tuple(c.effect for c in diagnosis.causes)
    judged = tuple(e for e in named if e in KEY_PARAMETER)
    if not judged:
        return ()
    rounds = diagnosis.selection.rounds
    base = diagnosis.base.model
    signals, rows = diagnosis.train.signals, diagnosis.train.rows
    current = diagnosis.designer.fit(joint_model(base, rounds, named), signals, rows)
    counts = encoder_counts(diagnosis.issues)
    found: list[Alias] = []
    for other in screened_effects(rounds):
        if other in named or other not in KEY_PARAMETER:
            continue
        joint = diagnosis.designer.fit(joint_model(base, rounds, (*named, other)), signals, rows)
        delta_bic = joint.bic - current.bic
        labels = KEY_LABELS.get(other) or tuple(
            label for label in joint.model.labels if label not in current.model.labels)
        statistic, threshold = wald(joint, labels)
        evidence = delta_bic <= EVIDENCE_BIC or statistic > threshold
        for cause in judged:
            instead_bic = math.nan
            if not evidence:  # nothing of E beside C: can E stand for C?
                swapped = tuple(other if e == cause else e for e in named)
                # judged as the best subset judged it: harmonic orders searched beside it
                model = researched_model(diagnosis.designer, signals, rows, counts, base,
                                         rounds, swapped)
                instead_bic = diagnosis.designer.fit(model, signals, rows).bic - current.bic
                if instead_bic >= -EVIDENCE_BIC:
                    continue
            before, after = _key_std(cause, current), _key_std(cause, joint)
            inflation = (after / before) ** 2 if before > 0 else math.nan
            if not math.isfinite(after) or inflation >= INFLATION:
                found.append(Alias(cause=cause, other=other, delta_bic=delta_bic,
                                   inflation=inflation if math.isfinite(after) else math.inf,
                                   instead_delta_bic=instead_bic,
                                   wald_statistic=statistic, wald_threshold=threshold))
    return tuple(found)


def _evidence_words(alias: Alias) -> str:
    """Why the data may hold ``alias.other``, in words (condition 1 of the module)."""
    if not math.isnan(alias.instead_delta_bic):
        return (f"{alias.other} in its place raises the BIC by only "
                f"{alias.instead_delta_bic:.3g}")
    if alias.delta_bic <= EVIDENCE_BIC:
        return f"{alias.other} lowers the BIC by {-alias.delta_bic:.3g}"
    return (f"{alias.other}'s coefficients beside it are significant (Wald "
            f"{alias.wald_statistic:.3g} > {alias.wald_threshold:.3g}) though the BIC "
            f"changes by {alias.delta_bic:+.3g}")


def excitation(cause: str, other: str) -> str:
    """What recording would separate ``cause`` from ``other``, in words.

    Parameters
    ----------
    cause, other : str

    Returns
    -------
    str
    """
    pair = {cause, other}
    if pair <= POSITION_EFFECTS:
        return ("over this travel they differ only by the cosine's curvature and the sine's "
                "cubic term: a longer travel (beyond ±1 rad), or a second run with the axis "
                "at another elevation (gravity turns with it, a spring and an offset do not), "
                "would separate them")
    if pair == {"cogging", "kt_ripple"}:
        return ("the same angles crossed at a different torque (K_t ripple scales with the "
                "torque, cogging does not) would separate them")
    return ("an excitation that moves them differently (e.g. a longer travel, slower "
            "constant-velocity steps, a wider frequency band) would separate them")


def declared(diagnosis: Diagnosis, found: tuple[Alias, ...], cause: str) -> dict[str, Any]:
    """What the report says about ``cause``'s confounding, fitted on every usable row.

    Parameters
    ----------
    diagnosis : Diagnosis
    found : tuple of Alias
        :func:`find`'s result.
    cause : str
        A named cause.

    Returns
    -------
    dict of str to Any
        Empty when ``cause`` is separable; else ``key`` (its key parameter), ``ci95``
        (the joint fits' 95 % intervals of it, to be joined with its own),
        ``not_separable_from`` {effect: ``parameters``, ``uncertainty`` of its key
        parameter in the joint fit, ``delta_bic``, ``inflation``} and ``note``.
    """
    mine = [a for a in found if a.cause == cause]
    if not mine:
        return {}
    named = tuple(c.effect for c in diagnosis.causes)
    signals, rows = diagnosis.estimation_rows
    key = KEY_PARAMETER[cause]
    low, high = math.inf, -math.inf
    others: dict[str, Any] = {}
    notes = []
    for alias in mine:
        model = joint_model(diagnosis.base.model, diagnosis.selection.rounds,
                            (*named, alias.other))
        fit = intervals.jackknife_fit(diagnosis.designer, diagnosis.designer.fit(
            model, signals, rows), signals, rows)
        coverage = intervals.JACKKNIFE_COVERAGE, intervals.JACKKNIFE_COVERAGE_99
        mine_named = interpret.effect_parameters(cause, fit, coverage=coverage[0],
                                                 coverage99=coverage[1])
        interval = mine_named["uncertainty"][key]["ci95"]
        if interval is None:
            interval = [-math.inf, math.inf]
        low, high = min(low, interval[0]), max(high, interval[1])
        theirs = interpret.effect_parameters(alias.other, fit, coverage=coverage[0],
                                             coverage99=coverage[1])
        other_key = KEY_PARAMETER[alias.other]
        others[alias.other] = {
            "parameters": {other_key: theirs["parameters"][other_key]},
            "uncertainty": {other_key: theirs["uncertainty"][other_key]},
            "delta_bic": alias.delta_bic,
            "inflation": alias.inflation,
            "instead_delta_bic": alias.instead_delta_bic,
            "wald_statistic": alias.wald_statistic,
        }
        evidence = _evidence_words(alias)
        notes.append(f"{cause} is not separable from {alias.other} in this recording "
                     f"(with {alias.other} beside it the {key} variance grows "
                     f"{alias.inflation:.3g}-fold, and {evidence}); "
                     f"{excitation(cause, alias.other)}")
    return {"key": key, "ci95": [low, high], "not_separable_from": others,
            "note": "; ".join(notes)}

