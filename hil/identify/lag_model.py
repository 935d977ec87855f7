"""The current loop's lag below its bandwidth: τ beside a dead time, and the first-order test.

:func:`hil.identify.current_loop.fit_current_loop_lag` fits ``1/(τ·s + 1)`` (with B/J) to
the lag phases at 20–150 Hz. A drive with a dead time as well (a computation delay, a PWM
update a period late, a command that acts late within its period) bends the phases away
from any first-order lag: ``atan(ωτ) + ωd`` against ``atan(ωτ')``, and the first-order τ' is
the equivalent of both over the band, above τ + d by about ``τ²·d·ω²`` at its top. A small
dead time is not seen by the first-order lag's χ² test (:func:`null_p_value`) and still
biases τ': over a second simulator's loops (300 units, commands acting 0–0.6 of a period
late), τ' read +0.9 to +1.7 % where the test held it adequate, and its ±U held the truth
for 57–68 % of those units. So the fit beside a dead time is made on every recording, and
the τ certified is its τ + d (:func:`certified`): the phase's slope at 0 Hz, the lag the
torque has below the band, which is what the sines take out and what a model of the loop
below its bandwidth needs. τ and d alone are nearly collinear over the band and are
stated, not certified. d is bounded below by 0 (a torque does not act before its command);
where the fit puts it there, the first-order τ is the fit and is certified. Over the same
units the certified τ read −0.05 %, its Type A ±U (k = 2) holding the truth for 97 % (RMS
of error/u 0.94), with u 1.0 × the first-order τ's (median; 0.2–2.1 × for 80 % of units, the
low end where the first-order fit's χ² had widened its own).
The χ² test still tells the certificate when the first-order lag does not describe the
phases, with d and τ.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from hil.gum import rounded_pair
from hil.identify.current_loop import (
    CurrentLoopResult,
    FloatArray,
    lag_phase_residual,
    scatter_dof,
)
from hil.identify.estimate import Estimate
from hil.identify.scatter_weights import DRAWS, chi2_p_value, coverage_dof, draw_fits

#: below this probability of a χ² as large, the first-order lag is rejected
ADEQUACY_P = 0.01
#: draws of the χ²'s null distribution (the p-value's own sd is ~0.0007 at 0.01)
NULL_DRAWS = DRAWS


@dataclass(frozen=True, slots=True, kw_only=True)
class LagModelCheck:
    """The first-order lag's χ² test, and the fit beside a dead time.

    Attributes
    ----------
    chi2_per_dof : float
        The first-order fit's χ²/ν.
    dof : int
        ν: frequencies − 2.
    p_value : float
        The probability of a χ² as large under the first-order model.
    dead_time_ms, dead_time_u_ms : float or None
        The dead time fitted beside τ and B/J (ms, ≥ 0) and its standard uncertainty
        (scaled by its own √(χ²/ν) when above one); ``None`` with fewer than four
        frequencies, 0 without u where the fit puts it at 0 (then every other field of that
        fit is ``None``: the first-order lag is the fit).
    time_constant_ms, time_constant_u_ms : float or None
        τ beside that dead time (ms), likewise.
    dead_time_chi2_per_dof : float or None
        That fit's χ²/ν (ν = frequencies − 3).
    low_frequency_lag_ms, low_frequency_lag_u_ms : float or None
        τ + dead time, the lag below the band (the phase's slope at 0 Hz), which that
        fit determines sharply where it cannot split the two, and its standard uncertainty.
    low_frequency_lag_crb_ms : float or None
        That sum's standard deviation from the fit's weights alone (its Cramér–Rao bound).
    low_frequency_lag_dof : float or None
        Its degrees of freedom, drawn as the first-order τ's are
        (:func:`hil.identify.scatter_weights.coverage_dof`).
    first_order_ms : float or None
        The first-order τ', the equivalent of τ and d over the band.
    """

    chi2_per_dof: float
    dof: int
    p_value: float
    dead_time_ms: float | None = None
    dead_time_u_ms: float | None = None
    time_constant_ms: float | None = None
    time_constant_u_ms: float | None = None
    dead_time_chi2_per_dof: float | None = None
    low_frequency_lag_ms: float | None = None
    low_frequency_lag_u_ms: float | None = None
    low_frequency_lag_crb_ms: float | None = None
    low_frequency_lag_dof: float | None = None
    first_order_ms: float | None = None

    @property
    def adequate(self) -> bool:
        """The first-order lag describes the phases (or there are too few to tell)."""
        return not self.p_value < ADEQUACY_P

    def message(self) -> str | None:
        """The certificate's line when the model is rejected, ``None`` when it holds."""
        if self.adequate:
            return None
        p_text = f"p = {self.p_value:.1e}" if self.p_value >= 1e-12 else "p < 1e-12"
        line = (f"the first-order current-loop lag does not describe the phases "
                f"(χ²/ν = {self.chi2_per_dof:.3g} on {self.dof}, {p_text}); ")
        if (self.dead_time_ms is None or self.dead_time_u_ms is None
                or self.time_constant_ms is None or self.time_constant_u_ms is None
                or self.first_order_ms is None):
            return line + "u(τ) is widened by √(χ²/ν)"
        dead, dead_u = rounded_pair(self.dead_time_ms, 2 * self.dead_time_u_ms)
        tau, tau_u = rounded_pair(self.time_constant_ms, 2 * self.time_constant_u_ms)
        return line + (
            f"a dead time of {dead} ± {dead_u} ms beside τ = {tau} ± {tau_u} ms (k = 2) does "
            f"(χ²/ν = {self.dead_time_chi2_per_dof:.3g}); the τ certified is their sum, the "
            f"lag below the band (the first-order τ, {self.first_order_ms:.4g} ms, is their "
            "equivalent over the band only)")


def check_lag_model(result: CurrentLoopResult, *, fs_hz: float, hold_s: float | None = None,
                    mean_samples: int = 1) -> LagModelCheck:
    """Test the first-order lag on the phases it was fitted to, and fit τ beside a dead time.

    Parameters
    ----------
    result : CurrentLoopResult
        The first-order fit (:func:`hil.identify.current_loop.fit_current_loop_lag`).
    fs_hz, hold_s, mean_samples
        As given to that fit.

    Returns
    -------
    LagModelCheck
    """
    dof = len(result.points) - 2
    if dof <= 0 or not math.isfinite(result.chi2_per_dof):
        return LagModelCheck(chi2_per_dof=result.chi2_per_dof, dof=dof, p_value=math.nan)
    p_value = null_p_value(result, fs_hz=fs_hz, hold_s=hold_s, mean_samples=mean_samples)
    check = LagModelCheck(chi2_per_dof=result.chi2_per_dof, dof=dof, p_value=p_value)
    if dof < 2:
        return check
    rate_hz = fs_hz if hold_s is None else 1.0 / hold_s
    residual = lag_phase_residual(result.points, fs_hz=rate_hz, mean_samples=mean_samples)
    tau_ms = result.time_constant.value
    fit = least_squares(residual, x0=np.array([tau_ms / 2, result.viscous_over_inertia_1_s,
                                               tau_ms / 2]),
                        bounds=([0.0, 0.0, 0.0], [1e3, 1e4, 1e3]))
    if fit.active_mask[2] != 0:  # no dead time: the first-order lag is the fit
        return replace(check, dead_time_ms=0.0, first_order_ms=tau_ms)
    jacobian = np.asarray(fit.jac, dtype=np.float64)
    try:
        covariance = np.linalg.inv(jacobian.T @ jacobian)
    except np.linalg.LinAlgError:
        return check
    chi2_per_dof = float(np.sum(fit.fun**2)) / (len(result.points) - 3)
    scale = max(1.0, chi2_per_dof)
    sum_variance = float(covariance[0, 0] + covariance[2, 2] + 2 * covariance[0, 2])
    drawn = draw_fits(jacobian, scatter_dof(result.points))
    return LagModelCheck(
        chi2_per_dof=result.chi2_per_dof, dof=dof, p_value=p_value,
        dead_time_ms=float(fit.x[2]), dead_time_u_ms=math.sqrt(covariance[2, 2] * scale),
        time_constant_ms=float(fit.x[0]), time_constant_u_ms=math.sqrt(covariance[0, 0] * scale),
        dead_time_chi2_per_dof=chi2_per_dof,
        low_frequency_lag_ms=float(fit.x[0] + fit.x[2]),
        low_frequency_lag_u_ms=math.sqrt(sum_variance * scale),
        low_frequency_lag_crb_ms=math.sqrt(sum_variance),
        low_frequency_lag_dof=coverage_dof(drawn, np.array([1.0, 0.0, 1.0]), inflated=scale > 1.0),
        first_order_ms=tau_ms,
    )


def null_p_value(result: CurrentLoopResult, *, fs_hz: float, hold_s: float | None = None,
                 mean_samples: int = 1, draws: int = NULL_DRAWS) -> float:
    """The probability of a χ² as large as the first-order fit's when the lag is first order.

    Each phase's weight is its block scatter's, an estimate with ``blocks − 1`` degrees of
    freedom, so each term of the χ² is an F(1, blocks − 1) rather than a χ²₁ (with 5 blocks
    the 1 % point of one term is 21.2, not 6.6). The null is drawn
    (:func:`hil.identify.scatter_weights.draw_fits`).
    """
    rate_hz = fs_hz if hold_s is None else 1.0 / hold_s
    residual = lag_phase_residual(result.points, fs_hz=rate_hz, mean_samples=mean_samples)
    x = np.array([result.time_constant.value, result.viscous_over_inertia_1_s])
    fits = draw_fits(_jacobian(residual, x), scatter_dof(result.points), draws=draws)
    return chi2_p_value(fits, result.chi2_per_dof * (len(result.points) - 2))


def _jacobian(residual: Callable[[FloatArray], FloatArray], x: FloatArray) -> FloatArray:
    """∂residual/∂x by central differences (steps relative to x, or 1e-6 at 0)."""
    columns = []
    for k in range(len(x)):
        step = np.zeros_like(x)
        step[k] = max(abs(float(x[k])), 1e-3) * 1e-6
        columns.append((residual(x + step) - residual(x - step)) / (2 * step[k]))
    return np.column_stack(columns)


def certified(result: CurrentLoopResult, check: LagModelCheck) -> CurrentLoopResult:
    """The fit with the τ to certify: τ + dead time (the module's text), or the first-order
    τ where the fit beside a dead time put it at 0 or there were too few frequencies.

    Parameters
    ----------
    result : CurrentLoopResult
        The first-order fit.
    check : LagModelCheck
        Its test (:func:`check_lag_model`).

    Returns
    -------
    CurrentLoopResult
        ``result`` itself, or with ``time_constant`` the sum, its u from the dead-time fit
        (scaled by √(χ²/ν) above one) with its drawn degrees of freedom.
    """
    if (check.low_frequency_lag_ms is None or check.low_frequency_lag_u_ms is None
            or check.low_frequency_lag_dof is None):
        return result
    first = result.time_constant
    lag = Estimate(name=first.name, value=check.low_frequency_lag_ms,
                   standard_uncertainty=check.low_frequency_lag_u_ms, unit=first.unit,
                   dof=check.low_frequency_lag_dof,
                   cramer_rao_std=check.low_frequency_lag_crb_ms)
    return replace(result, time_constant=lag)
