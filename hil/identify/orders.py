"""Orders per revolution in a residual: a least-squares periodogram against angle, and the
matching pursuit that picks the significant orders from it.

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

The residual may come in segments (e.g. the two constant-velocity passes of the cogging
protocol), each with its own angles and weight. Every segment gets its own amplitude and
phase of an order, and the order's power is the sum of the segments' powers: segments
whose harmonic differs in amplitude or sign (K_t ripple flips with the torque's sign
between an up and a down pass) add up instead of cancelling, as they would if the
segments were concatenated into one regression.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

BINS_PER_REV = 8192
MAX_ORDER = 200


@dataclass(frozen=True, slots=True, kw_only=True)
class Segment:
    """One stretch of residual against angle, with its own amplitude and phase per order.

    Attributes
    ----------
    residual : ndarray
        Effort residual (N·m).
    position_rad : ndarray
        Angle at each residual sample.
    weight : ndarray or None
        ``w`` per sample (``None`` for ``w = 1``).
    """

    residual: FloatArray
    position_rad: FloatArray
    weight: FloatArray | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class Periodogram:
    """Per-order power of a residual against angle.

    Attributes
    ----------
    orders : ndarray of int64
        Periods per revolution.
    power : ndarray
        RSS reduction per order (effort units squared), summed over the segments; 0 where
        an order's sine and cosine are not separable in a segment.
    chi2 : ndarray
        Per segment, power over the residual variance times the fraction of independent
        samples; summed over the segments (χ² with two degrees of freedom a segment).
    """

    orders: IntArray
    power: FloatArray  # RSS reduction per order (effort units squared)
    chi2: FloatArray  # power over the residual variance per effective sample


@dataclass(frozen=True, slots=True, kw_only=True)
class PursuitLimits:
    """When :func:`matching_pursuit` takes an order, and when it stops.

    An order is taken while all of these hold: its power is at least ``prominence`` times
    the periodogram's median away from the order's leakage, its χ² at least ``min_chi2``,
    its power at least ``relative_power`` times the first order's; and at most
    ``max_orders`` orders are taken in all.

    Attributes
    ----------
    prominence : float
        Power over the median power (orders further than three resolutions ``2π/travel``
        from the candidate).
    min_chi2 : float
        Least χ² (:attr:`Periodogram.chi2`); 0 to leave it out.
    relative_power : float
        Least fraction of the first order's power; 0 to leave it out.
    max_orders : int
        Most orders taken.
    """

    prominence: float
    min_chi2: float = 0.0
    relative_power: float = 0.0
    max_orders: int


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
    """One segment's binned angle grid with the per-order normal equations (weight only)."""

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
    # integer orders repeat every revolution: a travel over many folds onto one
    index = np.floor(np.mod(position_rad - origin, 2.0 * math.pi) / step).astype(np.intp)
    index = np.minimum(index, BINS_PER_REV - 1)
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
           independence: float) -> tuple[FloatArray, FloatArray]:
    """One segment's per-order power and χ²."""
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
    return power, chi2


def _weights(segments: Sequence[Segment]) -> list[FloatArray]:
    return [np.ones_like(s.residual) if s.weight is None else s.weight for s in segments]


def _gram(bases: Sequence[_Basis], residuals: Sequence[FloatArray],
          weights: Sequence[FloatArray], independence: float) -> Periodogram:
    power = np.zeros(len(bases[0].orders))
    chi2 = np.zeros(len(bases[0].orders))
    for basis, residual, weight in zip(bases, residuals, weights, strict=True):
        p, c = _power(basis, residual, weight, independence)
        power += p
        chi2 += c
    return Periodogram(orders=bases[0].orders, power=power, chi2=chi2)


def periodogram(
    segments: Sequence[Segment], *, orders: tuple[int, int], independence: float = 1.0
) -> Periodogram:
    """Per-order RSS reduction by ``w·[sin kθ, cos kθ]``, fitted to each segment on its own
    and summed over the segments.

    Parameters
    ----------
    segments : sequence of Segment
        The residual, in one or more segments.
    orders : (int, int)
        Inclusive range of orders (see :func:`order_range`).
    independence : float
        The fraction of samples that are statistically independent; it scales the χ²
        statistic.

    Returns
    -------
    Periodogram
        Empty when the range is, or there are no segments.
    """
    if orders[1] < orders[0] or not segments:
        empty = np.zeros(0)
        return Periodogram(orders=np.zeros(0, dtype=np.int64), power=empty, chi2=empty)
    weights = _weights(segments)
    bases = [_basis(s.position_rad, w, orders) for s, w in zip(segments, weights, strict=True)]
    return _gram(bases, [s.residual for s in segments], weights, independence)


def segment_amplitudes(
    segments: Sequence[Segment], *, orders: tuple[int, int]
) -> tuple[IntArray, NDArray[np.complex128]]:
    """Each segment's least-squares harmonic per order, fitted one order at a time.

    Parameters
    ----------
    segments : sequence of Segment
        The residual, in one or more segments.
    orders : (int, int)
        Inclusive range of orders (see :func:`order_range`).

    Returns
    -------
    orders : ndarray of int64
        The orders.
    amplitudes : ndarray of complex, shape (segments, orders)
        ``β + iα`` of ``w·(α·cos kθ + β·sin kθ)``, so that ``|z|`` is the amplitude and
        ``arg z`` the phase of ``w·A·sin(kθ + φ)``; 0 where the order's sine and cosine are
        not separable in a segment.
    """
    if orders[1] < orders[0] or not segments:
        return np.zeros(0, dtype=np.int64), np.zeros((len(segments), 0), dtype=np.complex128)
    weights = _weights(segments)
    rows = []
    basis = None
    for segment, weight in zip(segments, weights, strict=True):
        basis = _basis(segment.position_rad, weight, orders)
        s_wr = _binned(weight * segment.residual, basis.index, basis.size)[basis.used]
        b1, b2 = basis.sin @ s_wr, basis.cos @ s_wr
        a11, a12, a22 = basis.a11, basis.a12, basis.a22
        det = a11 * a22 - a12 * a12
        ok = det > 1e-12 * np.maximum(a11 * a22, 1e-300)
        safe = np.where(ok, det, 1.0)
        z = ((a22 * b1 - a12 * b2) + 1j * (a11 * b2 - a12 * b1)) / safe
        rows.append(np.where(ok, z, 0.0))
    assert basis is not None
    return basis.orders, np.asarray(rows, dtype=np.complex128)


def matching_pursuit(
    segments: Sequence[Segment],
    *,
    orders: tuple[int, int],
    limits: PursuitLimits,
    independence: float = 1.0,
) -> list[int]:
    """Significant orders, strongest first, by greedy matching pursuit over the
    :func:`periodogram`.

    The strongest order not yet taken is tested against ``limits``; when it passes it is
    regressed out of every segment (its own amplitude and phase in each) and the
    periodogram of what is left is taken again.

    Parameters
    ----------
    segments : sequence of Segment
        The residual, in one or more segments.
    orders : (int, int)
        Inclusive range of orders (see :func:`order_range`).
    limits : PursuitLimits
        The caller's thresholds and the most orders taken.
    independence : float
        As for :func:`periodogram`.

    Returns
    -------
    list of int
        The orders taken, in the order taken; empty when none is (or the range is empty).
    """
    if orders[1] < orders[0] or not segments:
        return []
    weights = _weights(segments)
    bases = [_basis(s.position_rad, w, orders) for s, w in zip(segments, weights, strict=True)]
    left = [s.residual.copy() for s in segments]
    # over part of a revolution an order leaks into its neighbours within a few times the
    # resolution 2π/travel (the shortest segment's, the widest leakage)
    travel = min(float(np.ptp(s.position_rad)) for s in segments)
    resolution = 2 * math.pi / max(travel, 1e-12)
    chosen: list[int] = []
    first_power = 0.0
    while len(chosen) < limits.max_orders:
        gram = _gram(bases, left, weights, independence)
        power = gram.power.copy()
        for k in chosen:
            power[gram.orders == k] = 0.0
        best = int(np.argmax(power))
        order = int(gram.orders[best])
        away = np.abs(gram.orders - order) > 3 * resolution
        floor = float(np.median(gram.power[away] if np.count_nonzero(away) > 10 else gram.power))
        if (
            power[best] < limits.prominence * floor
            or gram.chi2[best] < limits.min_chi2
            or power[best] < limits.relative_power * first_power
        ):
            break
        first_power = max(first_power, float(power[best]))
        chosen.append(order)
        for i, (segment, w) in enumerate(zip(segments, weights, strict=True)):
            theta = segment.position_rad
            columns = np.column_stack((w * np.sin(order * theta), w * np.cos(order * theta)))
            coef, *_ = np.linalg.lstsq(columns, left[i], rcond=None)
            left[i] = left[i] - columns @ coef
    return chosen
