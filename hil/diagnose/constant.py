"""A constant effort and a Coulomb difference between the directions: one column, two causes.

While the axis moves, friction that differs between the directions,
``T_c+`` moving positive and ``T_c−`` moving negative, is
``T_c·sgn ω − ΔT_c/2`` with ``T_c`` their mean and ``ΔT_c = T_c− − T_c+``: a constant, like
an offset ``c`` (a sensor's zero error, a gravity component along a linear axis). So
``ΔT_c = −2·c``, and no motion of the axis tells them apart: at standstill the band of
holding efforts is centred on ``c`` or on ``−ΔT_c/2`` alike, and neither depends on the
speed. The report therefore names the constant as ``offset`` with ``separable: false``
(and its equivalent Coulomb difference, with intervals), beside what the data identify on
their own (the viscous difference of ``asymmetric_friction``), and says in a ``note``
which measurement would separate them: one without friction in it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from hil.diagnose.interpret import FittedParameter
from hil.diagnose.model import Fit

if TYPE_CHECKING:
    from hil.diagnose.core import Diagnosis
    from hil.diagnose.select import Candidate

#: The Coulomb difference's coefficient in ``asymmetric_friction`` (its column is ``−½``).
DIFFERENCE = "coulomb_neg_delta"

NOTE = (
    "not separable: while the axis moves a constant effort and a Coulomb friction that "
    "differs between the directions are one column (coulomb_difference_nm = T_c- - T_c+ "
    "= -2 x offset_nm), and at standstill the holding effort is centred on either alike; "
    "no speed or standstill test separates them. A measurement without friction in it "
    "does: the drive's effort reading with the power stage off (a sensor offset reads "
    "non-zero), or the axis turned over or tilted (a gravity component changes sign, "
    "friction does not)"
)


def _estimate(fit: Fit, label: str, weight: float, coverage: float,
              coverage99: float) -> FittedParameter:
    """``weight × coefficient(label)`` with its standard deviation from ``fit``."""
    values, covariance = fit.block((label,))
    std = math.sqrt(float(covariance[0, 0])) if np.isfinite(covariance[0, 0]) else math.inf
    return FittedParameter(value=weight * float(values[0]), std=abs(weight) * std,
                           coverage=coverage, coverage99=coverage99)


def describe_offset(entry: dict[str, Any], fit: Fit, coverage: float,
                    coverage99: float) -> None:
    """Add to a named ``offset``'s entry the Coulomb difference it cannot be told from.

    Parameters
    ----------
    entry : dict of str to Any
        The cause's report entry (``parameters``, ``uncertainty``), changed in place:
        ``coulomb_difference_nm`` (``−2 × offset_nm``) with its uncertainty,
        ``separable: false`` and :data:`NOTE`.
    fit : Fit
        The cause's model with the jackknife covariance.
    coverage, coverage99 : float
        Coverage factors of the 95 % and 99 % intervals.
    """
    difference = _estimate(fit, "offset", -2.0, coverage, coverage99)
    entry["parameters"]["coulomb_difference_nm"] = difference.value
    entry["uncertainty"]["coulomb_difference_nm"] = difference.as_dict()
    entry["separable"] = False  # a note already there (an alias, alias.py) is kept
    entry["note"] = "; ".join(n for n in (entry.get("note"), NOTE) if n)


def offset_part(entry: dict[str, Any], candidate: Candidate, fit: Fit,
                diagnosis: Diagnosis, gain: Callable[[Candidate], dict[str, Any]],
                coverage: float, coverage99: float) -> dict[str, Any] | None:
    """The constant of a named ``asymmetric_friction`` as its own ``offset`` entry.

    The entry of the asymmetric friction is changed in place to what the data identify
    on their own: the viscous difference, and the mean Coulomb friction in both
    directions (``coulomb_pos_nm`` = ``coulomb_neg_nm``).

    Parameters
    ----------
    entry : dict of str to Any
        The ``asymmetric_friction`` cause's report entry.
    candidate : Candidate
        That cause as selected (its fit on the training rows).
    fit : Fit
        The same model with the jackknife covariance (every usable row).
    diagnosis : Diagnosis
        Gives the training and held-out rows to judge the constant on.
    gain : callable
        Lays out a candidate's gain for the report.
    coverage, coverage99 : float
        Coverage factors of the 95 % and 99 % intervals.

    Returns
    -------
    dict of str to Any or None
        ``None`` when the cause has no constant (an offset was in the model). Else the
        ``offset`` entry: ``offset_nm`` and ``coulomb_difference_nm`` with intervals,
        ``separable: false``, :data:`NOTE`, ``part_of: "asymmetric_friction"`` (a part of
        that cause's columns, not a cause selected on its own: its interval may hold
        zero), and the constant's own ``gain`` on top of the viscous difference (held out
        it may be none; the report does not hide it).
    """
    from hil.diagnose.select import Evaluator

    model = candidate.fit.model
    if DIFFERENCE not in model.labels:
        return None
    evaluator = Evaluator(diagnosis.designer, diagnosis.train, diagnosis.heldout, None)
    reduced = replace(model, terms=tuple(t for t in model.terms if DIFFERENCE not in t.labels))
    judged = evaluator.candidate("asymmetric_friction", model, evaluator.fit(reduced))
    coulomb = _estimate(fit, "coulomb", 1.0, coverage, coverage99)
    for name in ("coulomb_pos_nm", "coulomb_neg_nm"):
        entry["parameters"][name] = coulomb.value
        entry["uncertainty"][name] = coulomb.as_dict()
    entry["note"] = "; ".join(n for n in (
        entry.get("note"), "the Coulomb friction's difference between the directions is not "
        "separable from a constant: reported as the offset beside this cause") if n)
    offset = _estimate(fit, DIFFERENCE, -0.5, coverage, coverage99)
    difference = _estimate(fit, DIFFERENCE, 1.0, coverage, coverage99)
    return {
        "rank": entry["rank"] + 1,
        "name": "offset",
        "part_of": "asymmetric_friction",
        "parameters": {"offset_nm": offset.value, "coulomb_difference_nm": difference.value},
        "uncertainty": {"offset_nm": offset.as_dict(),
                        "coulomb_difference_nm": difference.as_dict()},
        "separable": False,
        "note": NOTE,
        "gain": gain(judged),
        "model_parameters": entry["model_parameters"],
    }
