"""From fitted coefficients to named physical parameters (with uncertainty) and plant fields.

Parameter names follow the report contract (``offset_nm``, ``coulomb_pos_nm``, ...). On a
linear axis the same names hold linear units (``offset_nm`` in N, ``inertia_kg_m2`` in
kg, ``viscous_nm_s_rad`` in N·s/m); :func:`units` gives the map the report carries.
Uncertainties are standard deviations from the fit's covariance (the report passes the
Newey–West one, :mod:`hil.diagnose.intervals`; delta method for derived values), with
95 % intervals ``value ± k·std`` and 99 % intervals ``value ± 2.576·std``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from hil.diagnose.model import Fit
from hil.recording import AxisKind

Z99 = 2.5758293035489004
#: K_t ripple's depth carries a method uncertainty of this fraction of itself beside the
#: jackknife's: on 29 simulated single ripples (``bench_diagnose.py --only kt_ripple
#: --hidden 30 --seed 11``) the depth's error RMS was 2.2 % against a jackknife u of 0.9 %
#: (median; a +1.5 % mean error near reversals, docs/diagnose.md, cause 4 of the ripple's
#: bias), so √(2.2² − 0.9²) ≈ 2 %.
KT_RIPPLE_METHOD_FRACTION = 0.02


@dataclass(frozen=True, slots=True, kw_only=True)
class FittedParameter:
    """A parameter of a fitted model with its standard deviation from the fit's covariance.

    Not a calibration result: those are :class:`hil.identify.estimate.Estimate`.

    Attributes
    ----------
    value : float
    std : float
        Standard deviation; infinite when the fit is rank-deficient, NaN when not
        estimated (a searched parameter).
    """

    value: float
    std: float
    coverage: float = 2.0
    coverage99: float = Z99

    def as_dict(self) -> dict[str, float | list[float] | None]:
        """``value``, ``std``, the 95 % interval ``ci95`` (``value ± coverage·std``) and the
        99 % interval ``ci99`` (``value ± coverage99·std``, by default 2.576).

        ``std``, ``ci95`` and ``ci99`` are ``None`` when ``std`` is not finite.
        """
        finite = math.isfinite(self.std)
        k = self.coverage
        return {
            "value": self.value,
            "std": self.std if finite else None,
            "ci95": [self.value - k * self.std, self.value + k * self.std] if finite else None,
            "ci99": ([self.value - self.coverage99 * self.std,
                      self.value + self.coverage99 * self.std] if finite else None),
        }


def _linear(fit: Fit, weights: dict[str, float], offset: float = 0.0) -> FittedParameter:
    """``offset + Σ w·coef`` with its standard deviation."""
    labels = tuple(weights)
    values, covariance = fit.block(labels)
    w = np.array([weights[label] for label in labels])
    variance = float(w @ covariance @ w) if np.all(np.isfinite(covariance)) else math.inf
    return FittedParameter(value=offset + float(w @ values), std=math.sqrt(max(variance, 0.0)))


def _amplitude(fit: Fit, sin_label: str, cos_label: str) -> tuple[FittedParameter, float]:
    """Amplitude (delta method) and phase of ``a·sin + b·cos = A·sin(x + φ)``."""
    (a, b), covariance = fit.block((sin_label, cos_label))
    amplitude = math.hypot(a, b)
    phase = math.atan2(b, a)
    if amplitude == 0.0 or not np.all(np.isfinite(covariance)):
        return FittedParameter(value=amplitude, std=math.inf), phase
    gradient = np.array([a, b]) / amplitude
    std = math.sqrt(max(float(gradient @ covariance @ gradient), 0.0))
    return FittedParameter(value=amplitude, std=std), phase


def units(axis_kind: AxisKind) -> dict[str, str]:
    """Unit of every reported quantity for this kind of axis.

    Parameters
    ----------
    axis_kind : {"rotary", "linear"}

    Returns
    -------
    dict of str to str
        Unit by reported name (or group of names).
    """
    rotary = axis_kind == "rotary"
    effort = "N·m" if rotary else "N"
    position = "rad" if rotary else "m"
    return {
        "effort (every *_nm)": effort,
        "inertia_kg_m2": "kg·m²" if rotary else "kg",
        "viscous_nm_s_rad, viscous_pos, viscous_neg": f"{effort}·s/{position}",
        "stribeck_velocity_rad_s": f"{position}/s",
        "stiffness_nm_per_rad": f"{effort}/{position}",
        "zero_rad": position,
        "relative_amplitude": "1",
        "periods_per_rev": "1/rev",
        "time_constant_s": "s",
        "resonance_hz": "Hz",
    }


def base_parameters(fit: Fit) -> dict[str, FittedParameter]:
    """J, B and T_c of ``fit``.

    Parameters
    ----------
    fit : Fit
        A model with the base terms.

    Returns
    -------
    dict of str to FittedParameter
        ``inertia_kg_m2``, ``viscous_nm_s_rad``, ``coulomb_nm``.
    """
    return {
        "inertia_kg_m2": _linear(fit, {"inertia": 1.0}),
        "viscous_nm_s_rad": _linear(fit, {"viscous": 1.0}),
        "coulomb_nm": _linear(fit, {"coulomb": 1.0}),
    }


def ripple_slope(coefficient: float) -> float:
    """``dA/dc`` of ``A = c/(1 + c²/4)`` (see :func:`_harmonics`).

    Parameters
    ----------
    coefficient : float
        The ripple column's fitted amplitude ``c``.

    Returns
    -------
    float
        ``(1 − c²/4)/(1 + c²/4)²``.
    """
    return (1 - coefficient**2 / 4) / (1 + coefficient**2 / 4) ** 2


def _harmonics(fit: Fit, effect: str) -> list[dict[str, float]]:
    term = fit.model.term(effect)
    if term is None:
        return []
    prefix = "cog" if effect == "cogging" else "kt"
    rows = []
    for label in term.labels[::2]:
        order = int(label.removeprefix(f"{prefix}_sin"))
        amplitude, phase = _amplitude(fit, f"{prefix}_sin{order}", f"{prefix}_cos{order}")
        value, std = amplitude.value, amplitude.std
        if effect == "kt_ripple":  # the drive reports T/(1 + r(θ)) ≈ T·(1 − r(θ))
            phase = math.remainder(phase + math.pi, 2 * math.pi)
            # exactly, 1/(1 + A·sin x) has the first harmonic c = 2(1 − √(1 − A²))/A of its
            # mean (which the load's coefficients take): A = c/(1 + c²/4) (+1 % at 0.2)
            value, std = value / (1 + value**2 / 4), std * ripple_slope(value)
        rows.append({"order": order, "amplitude": value, "amplitude_std": std,
                     "phase_rad": phase})
    rows.sort(key=lambda row: -row["amplitude"])
    return rows


def effect_parameters(effect: str, fit: Fit, *, lag_std_s: float = math.nan,
                      coverage: float = 2.0, coverage99: float = Z99,
                      method: bool = True) -> dict[str, Any]:
    """Named parameters of ``effect`` in ``fit``: values and :class:`FittedParameter` s.

    Parameters
    ----------
    effect : str
        One of :data:`hil.diagnose.effects.EFFECTS`; any other name gives empty tables.
    fit : Fit
        A model that contains ``effect``.
    lag_std_s : float
        Standard deviation of the current-loop time constant, s (used for
        ``current_lag``).
    coverage, coverage99 : float
        Coverage factors of the 95 % and 99 % intervals (from ``fit``'s covariance, and
        for the current-loop time constant from ``lag_std_s``).
    method : bool
        Add K_t ripple's method uncertainty (:data:`KT_RIPPLE_METHOD_FRACTION`) to its
        depth's; False: the fit's alone (for comparing fits).

    Returns
    -------
    dict of str to Any
        ``parameters``: every named value (report names, see ``docs/diagnose.md``),
        including those without an uncertainty (phases, orders, the two-mass fields);
        ``uncertainty``: :meth:`FittedParameter.as_dict` of those with one; ``note``, when
        a Coulomb asymmetry is not separable from the offset.

    Raises
    ------
    ValueError
        ``fit`` lacks the effect's coefficients (a ``cogging`` or ``kt_ripple`` term
        without orders gives amplitude 0 and order 0).
    """
    estimates: dict[str, FittedParameter] = {}
    extra: dict[str, Any] = {}
    lag = FittedParameter(value=fit.model.lag_s, std=lag_std_s)
    values = fit.as_dict()
    if effect == "offset":
        estimates["offset_nm"] = _linear(fit, {"offset": 1.0})
    elif effect == "asymmetric_friction":
        if "coulomb_neg_delta" in values:  # T_c·sgn ω − ΔT_c/2: |T_c±| = T_c ∓ ΔT_c/2
            estimates["coulomb_pos_nm"] = _linear(fit, {"coulomb": 1.0,
                                                        "coulomb_neg_delta": -0.5})
            estimates["coulomb_neg_nm"] = _linear(fit, {"coulomb": 1.0, "coulomb_neg_delta": 0.5})
        else:  # not separable from the offset already in the model
            estimates["coulomb_pos_nm"] = _linear(fit, {"coulomb": 1.0})
            estimates["coulomb_neg_nm"] = estimates["coulomb_pos_nm"]
            extra["note"] = "Coulomb asymmetry is not separable from the offset while moving"
        estimates["viscous_pos"] = _linear(fit, {"viscous": 1.0})
        estimates["viscous_neg"] = _linear(fit, {"viscous": 1.0, "viscous_neg_delta": 1.0})
    elif effect == "stribeck":
        term = fit.model.term("stribeck")
        estimates["static_torque_nm"] = _linear(fit, {"coulomb": 1.0, "stribeck_delta": 1.0})
        velocity = term.nonlinear["stribeck_velocity"] if term else math.nan
        estimates["stribeck_velocity_rad_s"] = FittedParameter(value=velocity, std=math.nan)
    elif effect in ("cogging", "kt_ripple"):
        rows = _harmonics(fit, effect)
        name = "amplitude_nm" if effect == "cogging" else "relative_amplitude"
        extra["periods_per_rev"] = rows[0]["order"] if rows else 0
        estimates[name] = (FittedParameter(value=rows[0]["amplitude"], std=rows[0]["amplitude_std"])
                           if rows else FittedParameter(value=0.0, std=math.nan))
        if effect == "kt_ripple" and method and rows:
            depth = estimates[name]
            estimates[name] = replace(depth, std=math.hypot(
                depth.std, KT_RIPPLE_METHOD_FRACTION * depth.value))
        extra["orders"] = [
            {"periods_per_rev": r["order"], name: r["amplitude"], "phase_rad": r["phase_rad"]}
            for r in rows
        ]
    elif effect == "gravity":
        mge, phase = _amplitude(fit, "gravity_sin", "gravity_cos")
        # a·cos θ + b·sin θ = mge·cos(θ + φ): a = mge·cos φ, b = −mge·sin φ
        a, b = values["gravity_cos"], values["gravity_sin"]
        estimates["mge_nm"] = mge
        extra["phase_rad"] = math.atan2(-b, a)
        del phase
    elif effect == "cable_spring":
        stiffness = _linear(fit, {"cable_stiffness": 1.0})
        estimates["stiffness_nm_per_rad"] = stiffness
        if "cable_constant" in values and stiffness.value != 0:
            extra["zero_rad"] = -values["cable_constant"] / stiffness.value
        else:
            extra["zero_rad"] = 0.0
        if "cable_hysteresis" in values:
            estimates["hysteresis_nm"] = _linear(fit, {"cable_hysteresis": 1.0})
            term = fit.model.term("cable_spring")
            if term is not None:
                extra["hysteresis_angle_rad"] = term.nonlinear["hysteresis_angle_rad"]
        else:
            extra["hysteresis_nm"] = 0.0
    elif effect == "current_lag":
        estimates["time_constant_s"] = lag
        # searched with τ: how many sample periods the friction's switching trails the motion
        extra["friction_delay_samples"] = fit.model.friction_delay
    elif effect == "two_mass":
        extra.update(two_mass_parameters(fit))
        estimates["load_inertia_kg_m2"] = _linear(fit, {"load_inertia": 1.0})
    estimates = {name: replace(e, coverage=coverage, coverage99=coverage99)
                 for name, e in estimates.items()}
    parameters: dict[str, Any] = {name: e.value for name, e in estimates.items()}
    parameters.update({k: v for k, v in extra.items() if k != "note"})
    result: dict[str, Any] = {
        "parameters": parameters,
        "uncertainty": {name: e.as_dict() for name, e in estimates.items()},
    }
    if "note" in extra:
        result["note"] = extra["note"]
    return result


def two_mass_parameters(fit: Fit) -> dict[str, float]:
    """The two-mass plant behind a fitted ``two_mass`` term.

    Parameters
    ----------
    fit : Fit

    Returns
    -------
    dict of str to float
        ``resonance_hz`` (NaN unless the motor inertia is positive), ``antiresonance_hz``,
        ``motor_inertia_kg_m2`` (J minus the load inertia), ``shaft_stiffness_nm_rad``,
        ``shaft_damping_nm_s_rad``, ``damping_ratio``; empty when ``fit`` has no
        ``two_mass`` term.
    """
    term = fit.model.term("two_mass")
    if term is None:
        return {}
    values = fit.as_dict()
    load = values["load_inertia"]
    motor = values["inertia"] - load
    antiresonance = term.nonlinear["antiresonance_hz"]
    damping = term.nonlinear["damping_ratio"]
    ratio = load / motor if motor > 0 else math.inf
    omega = 2 * math.pi * antiresonance
    return {
        "resonance_hz": antiresonance * math.sqrt(1 + ratio) if motor > 0 else math.nan,
        "antiresonance_hz": antiresonance,
        "motor_inertia_kg_m2": motor,
        "shaft_stiffness_nm_rad": omega**2 * load,
        "shaft_damping_nm_s_rad": 2 * damping * omega * load,
        "damping_ratio": damping,
    }
