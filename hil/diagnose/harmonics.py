"""Angle-domain periodogram: which orders per revolution does a residual contain?

Position is irregular in time (the axis speeds up, stops, reverses), so the spectrum is
taken against angle by least squares, order by order (a Lomb–Scargle periodogram in θ):
for each integer order ``k`` the residual is regressed on ``w·sin(kθ)`` and ``w·cos(kθ)``
(``w = 1`` for cogging, ``w = predicted torque`` for torque-proportional K_t ripple) and the
drop in the residual sum of squares is that order's power. The sums are accumulated in
fine angle bins first (8192 per revolution), which makes the cost independent of the
recording length.

Over less than a full revolution neighbouring orders are not orthogonal (an order leaks
into ``k ± 1, k ± 2``), so orders are picked greedily: the strongest order is regressed
out and the periodogram of what is left is taken again (matching pursuit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

BINS_PER_REV = 8192
#: Per-order χ²(2) threshold on the effective F statistic: p = 0.01 over 200 orders.
ORDER_MIN_CHI2 = -2.0 * math.log(0.01 / 200)
#: ... and the order must stand out of the periodogram (power over median power).
ORDER_PROMINENCE = 4.5
#: An order enters only when its power is at least this fraction of the first one's.
ORDER_RELATIVE_POWER = 0.02
MAX_ORDERS = 6
MAX_ORDER = 200


@dataclass(frozen=True, slots=True, kw_only=True)
class Periodogram:
    """Per-order power of a residual against angle.

    Attributes
    ----------
    orders : ndarray of int64
        Periods per revolution.
    power : ndarray
        RSS reduction per order (effort units squared); 0 where the order's sine and
        cosine are not separable.
    chi2 : ndarray
        Power over the residual variance, times the fraction of independent samples.
    """

    orders: IntArray
    power: FloatArray  # RSS reduction per order (effort units squared)
    chi2: FloatArray  # power over the residual variance per effective sample


def order_range(position_rad: FloatArray, counts_per_rev: int | None) -> tuple[int, int]:
    """Orders with at least two periods over the travel, resolvable by the encoder.

    Parameters
    ----------
    position_rad : ndarray
        The positions the residual is taken at.
    counts_per_rev : int or None
        Encoder counts per revolution; when given, orders are capped at
        ``counts_per_rev // 16``.

    Returns
    -------
    low, high : int
        The inclusive range: ``low = max(2, ⌈4π / travel⌉)``, ``high`` at most 200. An
        empty range (``high < low``) when the position does not move.
    """
    travel = float(np.ptp(position_rad))
    if travel <= 0:
        return (2, 1)
    low = max(2, math.ceil(2.0 * 2.0 * math.pi / travel))
    high = MAX_ORDER
    if counts_per_rev:
        high = min(high, counts_per_rev // 16)
    return (low, high)


def _binned(values: FloatArray, index: NDArray[np.intp], size: int) -> FloatArray:
    return np.bincount(index, weights=values, minlength=size).astype(np.float64)


@dataclass(frozen=True, slots=True, kw_only=True)
class _Basis:
    """Binned angle grid with the per-order normal equations (weight only)."""

    index: NDArray[np.intp]
    size: int
    used: NDArray[np.bool_]
    orders: IntArray
    sin: FloatArray
    cos: FloatArray
    a11: FloatArray
    a12: FloatArray
    a22: FloatArray


def _basis(position_rad: FloatArray, weight: FloatArray, orders: tuple[int, int]) -> _Basis:
    low, high = orders
    step = 2.0 * math.pi / BINS_PER_REV
    origin = float(np.min(position_rad))
    index = np.floor((position_rad - origin) / step).astype(np.intp)
    size = int(index.max()) + 1
    s_ww = _binned(weight * weight, index, size)
    used = s_ww > 0
    centres = origin + (np.arange(size)[used] + 0.5) * step
    ks = np.arange(low, high + 1, dtype=np.int64)
    phase = np.outer(ks, centres)
    sin, cos = np.sin(phase), np.cos(phase)
    s_ww = s_ww[used]
    return _Basis(index=index, size=size, used=used, orders=ks, sin=sin, cos=cos,
                  a11=(sin * sin) @ s_ww, a12=(sin * cos) @ s_ww, a22=(cos * cos) @ s_ww)


def _power(basis: _Basis, residual: FloatArray, weight: FloatArray,
           independence: float) -> Periodogram:
    s_wr = _binned(weight * residual, basis.index, basis.size)[basis.used]
    b1 = basis.sin @ s_wr
    b2 = basis.cos @ s_wr
    a11, a12, a22 = basis.a11, basis.a12, basis.a22
    det = a11 * a22 - a12 * a12
    ok = det > 1e-12 * np.maximum(a11 * a22, 1e-300)
    power = np.zeros(len(basis.orders))
    power[ok] = (a22 * b1 * b1 - 2 * a12 * b1 * b2 + a11 * b2 * b2)[ok] / det[ok]
    sigma2 = float(residual @ residual) / max(len(residual) - 2, 1)
    chi2 = power * independence / sigma2 if sigma2 > 0 else np.zeros_like(power)
    return Periodogram(orders=basis.orders, power=power, chi2=chi2)


def periodogram(
    residual: FloatArray,
    position_rad: FloatArray,
    *,
    weight: FloatArray | None = None,
    orders: tuple[int, int],
    independence: float = 1.0,
) -> Periodogram:
    """Per-order RSS reduction of ``residual`` by ``weight·[sin kθ, cos kθ]``.

    ``independence`` is the fraction of samples that are statistically independent; it
    scales the χ² statistic.

    Parameters
    ----------
    residual : ndarray
        Effort residual (N·m).
    position_rad : ndarray
        Angle at each residual sample.
    weight : ndarray, optional
        ``w`` per sample; default 1.
    orders : (int, int)
        Inclusive range of orders (see :func:`order_range`).
    independence : float

    Returns
    -------
    Periodogram
        Empty when the range is.
    """
    if orders[1] < orders[0]:
        empty = np.zeros(0)
        return Periodogram(orders=np.zeros(0, dtype=np.int64), power=empty, chi2=empty)
    w = np.ones_like(residual) if weight is None else weight
    return _power(_basis(position_rad, w, orders), residual, w, independence)


def find_orders(
    residual: FloatArray,
    position_rad: FloatArray,
    *,
    weight: FloatArray | None = None,
    orders: tuple[int, int],
    independence: float = 1.0,
) -> list[int]:
    """Significant orders, strongest first, by greedy matching pursuit.

    An order is taken while it is prominent (power ≥ 4.5 × the periodogram's median away
    from the order's leakage),
    significant (effective χ²(2) above the Bonferroni threshold for 200 orders at 1 %),
    at least 2 % of the first order's power, and at most six orders in all.

    Parameters
    ----------
    residual, position_rad, weight, orders, independence
        As for :func:`periodogram`.

    Returns
    -------
    list of int
        The orders taken, in the order taken; empty when none is (or the range is empty).
    """
    if orders[1] < orders[0]:
        return []
    w = np.ones_like(residual) if weight is None else weight
    basis = _basis(position_rad, w, orders)
    left = residual.copy()
    chosen: list[int] = []
    first_power = 0.0
    while len(chosen) < MAX_ORDERS:
        gram = _power(basis, left, w, independence)
        power = gram.power.copy()
        for k in chosen:
            power[gram.orders == k] = 0.0
        best = int(np.argmax(power))
        order = int(gram.orders[best])
        # noise floor away from the peak: over part of a revolution an order leaks into
        # its neighbours within a few times the resolution 2π/travel
        resolution = 2 * math.pi / max(float(np.ptp(position_rad)), 1e-12)
        away = np.abs(gram.orders - order) > 3 * resolution
        floor = float(np.median(gram.power[away] if np.count_nonzero(away) > 10 else gram.power))
        if (
            power[best] < ORDER_PROMINENCE * floor
            or gram.chi2[best] < ORDER_MIN_CHI2
            or power[best] < ORDER_RELATIVE_POWER * first_power
        ):
            break
        first_power = max(first_power, float(power[best]))
        chosen.append(order)
        columns = np.column_stack((w * np.sin(order * position_rad),
                                   w * np.cos(order * position_rad)))
        coef, *_ = np.linalg.lstsq(columns, left, rcond=None)
        left = left - columns @ coef
    return chosen
