"""Azimuth inertia across elevation: ``J(el) = J_zenith + ΔJ·cos²(el) + P·sin(2·el)`` from J
measured at several elevations of the other axis.

The elevation stage's inertia about its own frame (``I_a`` about the axis that is vertical
when level, ``I_b`` about the one that turns vertical at the zenith, ``P`` the product of
inertia between them) presents ``I_a·cos²(el) + I_b·sin²(el) + 2·P·sin(el)·cos(el)`` to
the azimuth axis: ``I_b + (I_a − I_b)·cos²(el) + P·sin(2·el)``, linear in its three
coefficients (Ekstrand 2001). Weighted least squares on the per-elevation J, weighted by
what differs between elevations (each J's Type A), gives J level (el = 0), J at the zenith
(el = π/2), the product of inertia P, and the ratio a fixed velocity-loop gain meets: the
largest over the smallest J on the elevation travel (with P ≠ 0 neither sits at 0 or π/2).
The fit covariance is scaled by ``√(χ²/ν)`` when the scatter about the model exceeds those
uncertainties. The Type B lines every J shares (the current loop's lag and the cable loop
taken out, the torque-reporting gain) are propagated through the fit as common inputs, once
and fully correlated: in the ratio they largely cancel.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from hil.errors import IdentificationError
from hil.identify.estimate import TYPE_A_SOURCE, Component, Estimate, with_budget

FloatArray = NDArray[np.float64]

#: the elevation travel assumed when the profile states none: a half turn (every J(el) seen)
HALF_TURN_RAD = (-math.pi / 2, math.pi / 2)
#: below this (smallest over largest singular value of the unit-scaled design) the
#: elevations do not tell P·sin(2el) from the other two terms
_SEPARABLE = 0.05


@dataclass(frozen=True, slots=True, kw_only=True)
class InertiaElevationResult:
    """Azimuth inertia across elevation, ``J(el) = J_zenith + ΔJ·cos²(el) + P·sin(2el)``.

    Attributes
    ----------
    elevations_rad : tuple of float
        Elevation of the other axis at each measurement (rad).
    inertias_kg_m2 : tuple of float
        J measured there (kg·m²).
    level : Estimate
        ``azimuth_inertia_level_kg_m2``: J at el = 0 (kg·m²).
    zenith : Estimate
        ``azimuth_inertia_zenith_kg_m2``: J at el = π/2 (kg·m²).
    product : Estimate
        ``azimuth_inertia_product_kg_m2``: P, the elevation stage's product of inertia.
    ratio : Estimate
        ``azimuth_inertia_ratio``: largest over smallest J on the travel.
    extremes_rad : tuple of float
        Elevations of the largest and the smallest J on the travel (rad).
    travel_rad : tuple of float
        The elevation travel the ratio is taken over (rad).
    chi2_per_dof : float
        χ² of the weighted fit per degree of freedom (elevations − 3); NaN with three.
    """

    elevations_rad: tuple[float, ...]
    inertias_kg_m2: tuple[float, ...]
    level: Estimate
    zenith: Estimate
    product: Estimate
    ratio: Estimate
    extremes_rad: tuple[float, float]
    travel_rad: tuple[float, float]
    chi2_per_dof: float


def regressors(elevation_rad: float) -> FloatArray:
    """``(1, cos²(el), sin(2el))``: J at ``elevation_rad`` is these times
    ``(J_zenith, ΔJ, P)``."""
    return np.array([1.0, math.cos(elevation_rad) ** 2, math.sin(2.0 * elevation_rad)])


def inertia_extremes_rad(
    coefficients: Sequence[float], travel_rad: tuple[float, float] = HALF_TURN_RAD
) -> tuple[float, float]:
    """Elevations of the largest and the smallest ``J(el)`` on ``travel_rad``.

    Parameters
    ----------
    coefficients : sequence of float
        ``(J_zenith, ΔJ, P)`` (kg·m²).
    travel_rad : tuple of float
        Lowest and highest elevation (rad).

    Returns
    -------
    tuple of float
        ``(el_max, el_min)``: among the travel's ends and the stationary points
        ``2el = atan2(2P, ΔJ) + kπ`` inside it.
    """
    _, delta, product = coefficients
    low, high = travel_rad
    phase = 0.5 * math.atan2(2.0 * product, delta)
    candidates = [low, high] + [phase + k * math.pi / 2 for k in range(-4, 5)
                                if low <= phase + k * math.pi / 2 <= high]
    values = [float(regressors(el) @ np.asarray(coefficients)) for el in candidates]
    return candidates[int(np.argmax(values))], candidates[int(np.argmin(values))]


def fit_inertia_elevation(
    elevations_rad: Sequence[float],
    inertias: Sequence[Estimate],
    *,
    travel_rad: tuple[float, float] = HALF_TURN_RAD,
) -> InertiaElevationResult:
    """Fit ``J = J_zenith + ΔJ·cos²(el) + P·sin(2el)`` to the inertia at several elevations.

    Parameters
    ----------
    elevations_rad : sequence of float
        Elevation of the other axis at each measurement (≥ 3, separating the three terms:
        elevations on both sides of level, or between level and the zenith).
    inertias : sequence of Estimate
        J measured there, with its uncertainty (the fit's weights).
    travel_rad : tuple of float
        The elevation axis's travel: the ratio is the largest over the smallest J on it.

    Returns
    -------
    InertiaElevationResult
        J level (el = 0), J zenith, P and the ratio as estimates, and the fit's χ²/dof.
        When χ²/dof exceeds one the uncertainties are scaled by its square root and carry
        ``elevations − 3`` degrees of freedom; otherwise infinite.

    Raises
    ------
    IdentificationError
        Fewer than three elevations or a length mismatch, elevations that do not separate
        the three terms, a travel that is not an interval, a J without a positive standard
        uncertainty, or a fitted J that is not positive on the travel.
    """
    if len(elevations_rad) != len(inertias) or len(inertias) < 3:
        raise IdentificationError("need J at 3 or more elevations")
    if not travel_rad[0] < travel_rad[1]:
        raise IdentificationError(f"the elevation travel {travel_rad} is not an interval")
    design = np.array([regressors(float(el)) for el in elevations_rad])
    singular = np.linalg.svd(design, compute_uv=False)
    if singular[-1] < _SEPARABLE * singular[0]:
        raise IdentificationError(
            "the elevations do not separate J_zenith, ΔJ·cos²(el) and P·sin(2el): add"
            " elevations on both sides of level (e.g. −1.2, 0, 0.6, 1.2 rad)")
    j = np.array([e.value for e in inertias])
    u = np.array([_independent_u(e) for e in inertias])
    if np.any(u <= 0):
        raise IdentificationError("every J needs a positive standard uncertainty")
    weighted = design / u[:, None]
    coefficients, *_ = np.linalg.lstsq(weighted, j / u, rcond=None)
    residual = j / u - weighted @ coefficients
    dof = len(j) - 3
    chi2_per_dof = float(residual @ residual) / dof if dof > 0 else math.nan
    normal_inverse = np.linalg.inv(weighted.T @ weighted)
    covariance = normal_inverse * (max(1.0, chi2_per_dof) if dof > 0 else 1.0)
    effective_dof = float(dof) if dof > 0 and chi2_per_dof > 1.0 else math.inf
    el_max, el_min = inertia_extremes_rad(coefficients, travel_rad)
    j_max, j_min = float(regressors(el_max) @ coefficients), float(
        regressors(el_min) @ coefficients)
    if j_min <= 0:
        raise IdentificationError(
            f"the fitted J is not positive at elevation {el_min:.2f} rad ({j_min:.3g} kg·m²)")
    # d(coefficients)/d(J_i): how an input common to every J moves the fit
    response = normal_inverse @ weighted.T / u[None, :]
    shared = _shared_inputs(inertias)
    # each result is a function of the coefficients: (value, gradient, unit); the ratio's
    # gradient holds the extremes' elevations fixed (they are stationary or at the ends)
    results = {
        "azimuth_inertia_level_kg_m2": (float(regressors(0.0) @ coefficients),
                                        regressors(0.0), "kg·m²"),
        "azimuth_inertia_zenith_kg_m2": (float(coefficients[0]), np.array([1.0, 0.0, 0.0]),
                                         "kg·m²"),
        "azimuth_inertia_product_kg_m2": (float(coefficients[2]), np.array([0.0, 0.0, 1.0]),
                                          "kg·m²"),
        "azimuth_inertia_ratio": (j_max / j_min, regressors(el_max) / j_min
                                  - j_max * regressors(el_min) / j_min**2, "1"),
    }
    estimates = {}
    for name, (value, gradient, unit) in results.items():
        lines = [Component(source=TYPE_A_SOURCE, kind="A", unit=unit, dof=effective_dof,
                           standard_uncertainty=math.sqrt(float(gradient @ covariance
                                                                @ gradient)))]
        lines += [replace(line, sensitivity=float(gradient @ response @ sensitivities))
                  for line, sensitivities in shared]
        estimates[name] = with_budget(
            Estimate(name=name, value=value, standard_uncertainty=0.0, unit=unit),
            [line for line in lines if line.contribution > 0], value=value)
    return InertiaElevationResult(
        elevations_rad=tuple(float(e) for e in elevations_rad),
        inertias_kg_m2=tuple(float(v) for v in j),
        level=estimates["azimuth_inertia_level_kg_m2"],
        zenith=estimates["azimuth_inertia_zenith_kg_m2"],
        product=estimates["azimuth_inertia_product_kg_m2"],
        ratio=estimates["azimuth_inertia_ratio"],
        extremes_rad=(el_max, el_min),
        travel_rad=travel_rad,
        chi2_per_dof=chi2_per_dof,
    )


def _independent_u(inertia: Estimate) -> float:
    """The part of J's uncertainty its own sines' data give (Type A): what differs from
    one elevation to the next."""
    return math.sqrt(sum(c.contribution**2 for c in inertia.components() if c.kind == "A"))


def _shared_inputs(inertias: Sequence[Estimate]) -> list[tuple[Component, FloatArray]]:
    """The Type B lines: earlier results (lag, cable loop, gain) every J takes out alike,
    each with its sensitivity at every elevation (0 where a J lacks it). Counted once,
    fully correlated; in the ratio they largely cancel."""
    lines: dict[str, tuple[Component, FloatArray]] = {}
    for i, inertia in enumerate(inertias):
        for line in inertia.components():
            if line.kind == "B":
                _, sensitivities = lines.setdefault(
                    line.source, (line, np.zeros(len(inertias))))
                sensitivities[i] = line.sensitivity
    return list(lines.values())


def scale_by_gain(estimate: Estimate, *, gain: float, gain_u: float) -> Estimate:
    """J in shaft-torque units: ``J_reported · gain``.

    Parameters
    ----------
    estimate : Estimate
        J from the reported torque.
    gain : float
        Shaft torque / reported torque (the torque-constant protocol's result).
    gain_u : float
        Standard uncertainty of ``gain``.

    Returns
    -------
    Estimate
        ``estimate`` times ``gain``: every budget line of ``estimate`` scaled by ``gain``
        and the gain's own line (sensitivity ``J_reported``).
    """
    gain_line = Component(source="torque-reporting gain, shaft/reported (torque_constant)",
                          kind="B", standard_uncertainty=gain_u, unit="1",
                          sensitivity=estimate.value)
    return estimate.scaled(gain, name=estimate.name, unit=estimate.unit).with_components(
        gain_line)
