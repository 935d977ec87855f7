"""Azimuth inertia across elevation: ``J(el) = J_zenith + ΔJ·cos²(el)`` from J measured at
several elevations of the other axis.

A payload with principal inertias ``I_a`` (about the axis that is vertical when level) and
``I_b`` (the one that turns vertical at the zenith) presents ``I_a·cos²(el) + I_b·sin²(el)``
to the azimuth axis, i.e. ``I_b + (I_a − I_b)·cos²(el)``: linear in ``cos²(el)``. Weighted
least squares on the per-elevation J and their standard uncertainties; the results are J
level (el = 0) and at the zenith (el = π/2) with the fit covariance, scaled by ``√(χ²/ν)``
when the scatter about the line exceeds the stated uncertainties.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hil.errors import IdentificationError
from hil.identify.estimate import Component, Estimate


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
    u = np.array([e.standard_uncertainty for e in inertias])
    if np.any(u <= 0):
        raise IdentificationError("every J needs a positive standard uncertainty")
    design = np.column_stack([np.ones_like(c2), c2]) / u[:, None]
    coefficients, *_ = np.linalg.lstsq(design, j / u, rcond=None)
    residual = j / u - design @ coefficients
    dof = len(j) - 2
    chi2_per_dof = float(residual @ residual) / dof if dof > 0 else math.nan
    covariance = np.linalg.inv(design.T @ design) * (max(1.0, chi2_per_dof) if dof > 0 else 1.0)
    at_level = np.array([1.0, 1.0])
    zenith_value, delta = float(coefficients[0]), float(coefficients[1])
    effective_dof = float(dof) if dof > 0 and chi2_per_dof > 1.0 else math.inf
    return InertiaElevationResult(
        elevations_rad=tuple(float(e) for e in elevations_rad),
        inertias_kg_m2=tuple(float(v) for v in j),
        level=Estimate(name="azimuth_inertia_level_kg_m2", value=zenith_value + delta,
                       standard_uncertainty=math.sqrt(float(at_level @ covariance @ at_level)),
                       unit="kg·m²", dof=effective_dof),
        zenith=Estimate(name="azimuth_inertia_zenith_kg_m2", value=zenith_value,
                        standard_uncertainty=math.sqrt(float(covariance[0, 0])), unit="kg·m²",
                        dof=effective_dof),
        ratio=_ratio(zenith_value, delta, covariance, effective_dof),
        chi2_per_dof=chi2_per_dof,
    )


def _ratio(zenith: float, delta: float, covariance: NDArray[np.float64], dof: float) -> Estimate:
    """``(J_zenith + ΔJ) / J_zenith``, the max/min inertia a fixed velocity-loop gain sees
    (the loop's crossover moves by the same factor); first-order propagation."""
    gradient = np.array([-delta / zenith**2, 1.0 / zenith])
    return Estimate(name="azimuth_inertia_ratio", value=1.0 + delta / zenith,
                    standard_uncertainty=math.sqrt(float(gradient @ covariance @ gradient)),
                    unit="1", dof=dof)


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
