"""Whether the current loop's first-order lag describes the phases it was fitted to.

:func:`hil.identify.current_loop.fit_current_loop_lag` fits ``1/(τ·s + 1)`` (with B/J) to
the lag phases at 20–150 Hz and widens u(τ) by ``√(χ²/ν)``. A drive with a dead time as well
(a computation delay, a PWM update a period late, a command that acts late within its
period) bends the phases away from any first-order lag: ``atan(ωτ) + ωd`` against
``atan(ωτ')``. The first-order τ is then the equivalent of both, larger than τ + d at the top
of the band. This tests the first-order model on its own data (χ² against its degrees of
freedom) and, when it is rejected, fits τ beside a dead time to say what would describe
the phases. The two are nearly collinear over the band (only their sum is sharp), so that
fit is stated, not certified.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats
from scipy.optimize import least_squares

from hil.gum import rounded_pair
from hil.identify.current_loop import CurrentLoopResult, sampled_response

#: below this probability of a χ² as large, the first-order lag is rejected
ADEQUACY_P = 0.01


@dataclass(frozen=True, slots=True, kw_only=True)
class LagModelCheck:
    """The first-order lag's χ² test, and the dead-time fit when it fails.

    Attributes
    ----------
    chi2_per_dof : float
        The first-order fit's χ²/ν.
    dof : int
        ν: frequencies − 2.
    p_value : float
        The probability of a χ² as large under the first-order model.
    dead_time_ms, dead_time_u_ms : float or None
        The dead time fitted beside τ and B/J (ms) and its standard uncertainty (scaled by
        its own √(χ²/ν) when above one); ``None`` when the first-order lag holds.
    time_constant_ms, time_constant_u_ms : float or None
        τ beside that dead time (ms), likewise.
    dead_time_chi2_per_dof : float or None
        That fit's χ²/ν (ν = frequencies − 3).
    """

    chi2_per_dof: float
    dof: int
    p_value: float
    dead_time_ms: float | None = None
    dead_time_u_ms: float | None = None
    time_constant_ms: float | None = None
    time_constant_u_ms: float | None = None
    dead_time_chi2_per_dof: float | None = None

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
                f"(χ²/ν = {self.chi2_per_dof:.3g} on {self.dof}, {p_text}); "
                f"u(τ) is widened by √(χ²/ν)")
        if (self.dead_time_ms is not None and self.dead_time_u_ms is not None
                and self.time_constant_ms is not None and self.time_constant_u_ms is not None):
            dead, dead_u = rounded_pair(self.dead_time_ms, 2 * self.dead_time_u_ms)
            tau, tau_u = rounded_pair(self.time_constant_ms, 2 * self.time_constant_u_ms)
            line += (f"; a dead time of {dead} ± {dead_u} ms beside τ = {tau} ± {tau_u} ms "
                     f"(k = 2) would (χ²/ν = {self.dead_time_chi2_per_dof:.3g}): the τ "
                     "certified is the first-order equivalent of both")
        return line


def check_lag_model(result: CurrentLoopResult, *, fs_hz: float, hold_s: float | None = None,
                    mean_samples: int = 1) -> LagModelCheck:
    """Test the first-order lag on the phases it was fitted to; fit a dead time beside it
    when it fails.

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
    p_value = float(stats.chi2.sf(result.chi2_per_dof * dof, dof))
    check = LagModelCheck(chi2_per_dof=result.chi2_per_dof, dof=dof, p_value=p_value)
    if check.adequate or dof < 2:
        return check
    rate_hz = fs_hz if hold_s is None else 1.0 / hold_s
    freqs = np.array([p.frequency_hz for p in result.points])
    phases = np.array([p.lag_phase_rad for p in result.points])
    sigma = np.array([max(p.lag_phase_u_rad, 1e-6) for p in result.points])
    omega = 2 * math.pi * freqs
    rigid = sampled_response(freqs, fs_hz=rate_hz, inertia_kg_m2=1.0,
                             viscous_over_inertia_1_s=0.0, time_constant_s=0.0,
                             mean_samples=mean_samples)

    def residual(x: np.ndarray) -> np.ndarray:
        model = sampled_response(freqs, fs_hz=rate_hz, inertia_kg_m2=1.0,
                                 viscous_over_inertia_1_s=float(x[1]),
                                 time_constant_s=float(x[0]) * 1e-3,
                                 mean_samples=mean_samples) * np.exp(-1j * omega * x[2] * 1e-3)
        return np.asarray((np.angle(model / rigid) - phases) / sigma, dtype=np.float64)

    tau_ms = result.time_constant.value
    fit = least_squares(residual, x0=np.array([tau_ms / 2, result.viscous_over_inertia_1_s,
                                               tau_ms / 2]),
                        bounds=([0.0, 0.0, 0.0], [1e3, 1e4, 1e3]))
    jacobian = np.asarray(fit.jac, dtype=np.float64)
    try:
        covariance = np.linalg.inv(jacobian.T @ jacobian)
    except np.linalg.LinAlgError:
        return check
    chi2_per_dof = float(np.sum(fit.fun**2)) / (len(freqs) - 3)
    scale = max(1.0, chi2_per_dof)
    return LagModelCheck(
        chi2_per_dof=result.chi2_per_dof, dof=dof, p_value=p_value,
        dead_time_ms=float(fit.x[2]), dead_time_u_ms=math.sqrt(covariance[2, 2] * scale),
        time_constant_ms=float(fit.x[0]), time_constant_u_ms=math.sqrt(covariance[0, 0] * scale),
        dead_time_chi2_per_dof=chi2_per_dof,
    )
