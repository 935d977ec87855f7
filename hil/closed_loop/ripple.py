"""Residual cogging in the motion: the position ripple at the cogging orders of a
constant-velocity pass.

What a cogging torque leaves in a velocity-controlled motion is a position ripple at its
orders: ``θ(t) = θ₀ + v·t + Σ aₙ·sin(n·θ) + bₙ·cos(n·θ)`` (the loop's rejection decides the
size). A least-squares fit of the encoder position on a cubic in time and the harmonics of
the measured angle at the table's orders gives each order's amplitude ``√(aₙ² + bₙ²)``; the
residual ripple is the largest. Applied compensation (the drive adds the table's torque)
shrinks it; the ratio of the ripple without to with is the compensation's effectiveness.

Type A: the fit's Newey–West covariance, propagated to the amplitude of the largest order
(``u = √(gᵀ Σ g)`` with ``g`` the amplitude's gradient). The residual is white reading
noise plus a velocity loop's slow wander, which has its power at the ripple's own few
periods (a 1.3 s pass holds 3–6 of them): a bandwidth fitted to the residual's first lags
sees the white part and states a quarter of the scatter. The bandwidth is therefore a
fixed share of the pass, a quarter (Kiefer & Vogelsang's fixed-b: Bartlett at b = ¼ is
nearly unbiased for such noise, and its own scatter is that of a variance with
``3/(2b) = 6`` degrees of freedom, which the line states).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from hil.errors import IdentificationError
from hil.identify.estimate import Component, Estimate, with_budget
from hil.identify.regression import newey_west_covariance

FloatArray = NDArray[np.float64]
BANDWIDTH_SHARE = 4  # Newey–West lags: the pass over this (b = 1/4)
DOF = 1.5 * BANDWIDTH_SHARE  # of the Bartlett estimate at that bandwidth, 3/(2b)


def position_ripple(time_s: FloatArray, position_rad: FloatArray, *, orders: Sequence[int]
                    ) -> tuple[float, float, int]:
    """Largest position ripple amplitude at ``orders`` (rad), its standard uncertainty and
    its order.

    Raises
    ------
    IdentificationError
        No orders, or fewer samples than twice the fit's columns.
    """
    if not orders:
        raise IdentificationError("no cogging orders to measure the ripple at")
    t = (time_s - time_s.mean()) / max(float(np.ptp(time_s)), 1e-12)
    columns = [np.ones_like(t), t, t**2, t**3]
    for n in orders:
        columns += [np.sin(n * position_rad), np.cos(n * position_rad)]
    design = np.column_stack(columns)
    if design.shape[0] < 2 * design.shape[1]:
        raise IdentificationError("too few samples for the ripple fit")
    coef, *_ = np.linalg.lstsq(design, position_rad, rcond=None)
    residual = position_rad - design @ coef
    cov = newey_west_covariance(design, residual, lags=max(1, len(residual) // BANDWIDTH_SHARE))
    amplitudes = [math.hypot(coef[4 + 2 * i], coef[5 + 2 * i]) for i in range(len(orders))]
    i = int(np.argmax(amplitudes))
    a, b = coef[4 + 2 * i], coef[5 + 2 * i]
    amp = amplitudes[i]
    grad = np.array([a / amp, b / amp]) if amp > 0 else np.array([1.0, 0.0])
    block = cov[4 + 2 * i: 6 + 2 * i, 4 + 2 * i: 6 + 2 * i]
    return amp, float(math.sqrt(max(grad @ block @ grad, 0.0))), int(orders[i])


def ripple_estimate(name: str, amplitude_rad: float, u_rad: float, *, order: int
                    ) -> Estimate:
    """The ripple in µrad with its Type A line."""
    line = Component(source=f"fit of the position ripple at order {order} (Newey–West, "
                            "Type A)", kind="A", standard_uncertainty=u_rad * 1e6, unit="µrad",
                     dof=DOF)
    base = Estimate(name=name, value=amplitude_rad * 1e6, standard_uncertainty=0.0,
                    unit="µrad")
    return with_budget(base, [line], value=amplitude_rad * 1e6)
