"""Azimuth inertia across elevation: ``J(el) = J_zenith + ΔJ·cos²(el)`` from J measured at
several elevations of the other axis.

A payload with principal inertias ``I_a`` (about the axis that is vertical when level) and
``I_b`` (the one that turns vertical at the zenith) presents ``I_a·cos²(el) + I_b·sin²(el)``
to the azimuth axis, i.e. ``I_b + (I_a − I_b)·cos²(el)``: linear in ``cos²(el)``. Weighted
least squares on the per-elevation J, weighted by what differs between elevations (each
J's Type A); the results are J level (el = 0), at the zenith (el = π/2) and their ratio,
with the fit covariance, scaled by ``√(χ²/ν)`` when the scatter about the line exceeds
those uncertainties. The Type B lines every J shares (the current loop's lag and the cable
loop taken out, the torque-reporting gain) are propagated through the fit as common
inputs, once and fully correlated: in the ratio they largely cancel.
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


@dataclass(frozen=True, slots=True, kw_only=True)
class InertiaElevationResult:
    """Azimuth inertia across elevation, ``J(el) = J_zenith + ΔJ·cos²(el)``.

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
    ratio : Estimate
        ``azimuth_inertia_ratio``: J level / J zenith (max/min over elevation).
    chi2_per_dof : float
        χ² of the weighted fit per degree of freedom (elevations − 2).
    """

    elevations_rad: tuple[float, ...]
    inertias_kg_m2: tuple[float, ...]
    level: Estimate  # azimuth_inertia_level_kg_m2
    zenith: Estimate  # azimuth_inertia_zenith_kg_m2
    ratio: Estimate  # azimuth_inertia_ratio: J level / J zenith (max/min over elevation)
    chi2_per_dof: float


def fit_inertia_elevation(
    elevations_rad: Sequence[float], inertias: Sequence[Estimate]
) -> InertiaElevationResult:
    """Fit ``J = J_zenith + ΔJ·cos²(el)`` to the inertia measured at several elevations.

    Parameters
    ----------
    elevations_rad : sequence of float
        Elevation of the other axis at each measurement (≥ 3, spanning different cos²).
    inertias : sequence of Estimate
        J measured there, with its uncertainty (the fit's weights).

    Returns
    -------
    InertiaElevationResult
        J level (el = 0), J zenith and their ratio (max/min over elevation) as estimates,
        and the fit's χ²/dof. When χ²/dof exceeds one the uncertainties are scaled by its
        square root and carry ``elevations − 2`` degrees of freedom; otherwise infinite.

    Raises
    ------
    IdentificationError
        Fewer than three elevations or a length mismatch, elevations spanning less than
        0.3 of cos²(el), or a J without a positive standard uncertainty.
    """
    if len(elevations_rad) != len(inertias) or len(inertias) < 3:
        raise IdentificationError("need J at 3 or more elevations")
    c2 = np.cos(np.asarray(elevations_rad, dtype=np.float64)) ** 2
    if float(np.ptp(c2)) < 0.3:
        raise IdentificationError("the elevations do not span enough of cos²(el)")
    j = np.array([e.value for e in inertias])
    u = np.array([_independent_u(e) for e in inertias])
    if np.any(u <= 0):
        raise IdentificationError("every J needs a positive standard uncertainty")
    design = np.column_stack([np.ones_like(c2), c2])
    weighted = design / u[:, None]
    coefficients, *_ = np.linalg.lstsq(weighted, j / u, rcond=None)
    residual = j / u - weighted @ coefficients
    dof = len(j) - 2
    chi2_per_dof = float(residual @ residual) / dof if dof > 0 else math.nan
    normal_inverse = np.linalg.inv(weighted.T @ weighted)
    covariance = normal_inverse * (max(1.0, chi2_per_dof) if dof > 0 else 1.0)
    zenith_value, delta = float(coefficients[0]), float(coefficients[1])
    effective_dof = float(dof) if dof > 0 and chi2_per_dof > 1.0 else math.inf
    # d(coefficients)/d(J_i): how an input common to every J moves the fit
    response = normal_inverse @ weighted.T / u[None, :]
    shared = _shared_inputs(inertias)
    results = {
        "azimuth_inertia_level_kg_m2": (zenith_value + delta, np.array([1.0, 1.0]), "kg·m²"),
        "azimuth_inertia_zenith_kg_m2": (zenith_value, np.array([1.0, 0.0]), "kg·m²"),
        # (J_zenith + ΔJ)/J_zenith, the max/min inertia a fixed velocity-loop gain sees
        "azimuth_inertia_ratio": (1.0 + delta / zenith_value,
                                  np.array([-delta / zenith_value**2, 1.0 / zenith_value]), "1"),
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
        ratio=estimates["azimuth_inertia_ratio"],
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
