"""Cogging torque and K_t ripple from constant-velocity passes at two torque levels.

At constant speed the motor delivers ``T_cmd·(1 + r(θ)) = L(θ) ± F + g(θ)``: smooth load
``L`` (gravity, cable), sliding friction ``F`` (sign of the direction), cogging ``g(θ)``
and the K_t ripple ``r(θ)``. To first order the commanded torque's position harmonic of
order ``n`` is ``C_n = G_n − T̄·R_n`` with ``T̄`` the pass's mean torque level: cogging is
the same in both passes, K_t ripple scales with the torque. Two passes with different
``T̄`` (up and down: ``T̄± = L̄ ± F``) therefore separate them::

    R_n = −(C₊ − C₋)/(T̄₊ − T̄₋),      G_n = C₊ + T̄₊·R_n

Complex amplitudes ``z = A·e^{iφ}`` stand for ``A·sin(nθ + φ)`` (the simulator's
convention). Orders are found by the matching pursuit of :mod:`hil.identify.orders` over
the two passes' residuals about their smooth trend, each pass a segment with its own
amplitude and phase (K_t ripple flips sign between the passes, so they cannot be
concatenated), then fitted jointly with a polynomial for the smooth part. Orders below
``min_order`` (a few cycles over the travel) cannot be told from the smooth load and are
not sought.

Compensation table (JSON, written by the protocol next to the certificate)::

    {"format": "gimbal-hil cogging compensation 1",
     "model": "T_ff(θ) = Σ cogging A_n·sin(n·θ + φ_n);
               K_t(θ) = K_t·(1 + Σ kt_ripple a_n·sin(n·θ + ψ_n))",
     "angle": "motor position in rad, encoder zero", "cogging": [{"order", "amplitude_nm",
     "phase_rad", "amplitude_u_nm"}], "kt_ripple": [{"order", "amplitude", "phase_rad",
     "amplitude_u"}]}

A drive compensates by adding ``T_ff(θ)`` to its torque command and dividing by
``1 + r(θ)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hil.errors import IdentificationError
from hil.identify.estimate import Component, Estimate
from hil.identify.harmonic_fit import harmonic_columns, polynomial_columns
from hil.identify.orders import (
    PursuitLimits,
    Segment,
    matching_pursuit,
    segment_amplitudes,
)
from hil.identify.quantisation import quantisation_step

FloatArray = NDArray[np.float64]
COMPENSATION_FORMAT = "gimbal-hil cogging compensation 1"
#: An order is taken when its power, summed over the two passes, is at least this many
#: times the median power (away from its leakage). The two passes' noise adds up in the
#: sum (σ²·χ²(4), median 3.36 σ²): an order carried by one pass alone, as K_t ripple is
#: when one torque level is near zero, then stands 1.228/1.678 × as far above the floor as
#: it would over one pass (median of the larger of two χ²(2) over the median of their sum),
#: and ``64 × 1.228/1.678 ≈ 47`` keeps the detection limit of an amplitude 8 × the median
#: in the stronger pass; an order in both passes stands out more.
PROMINENCE = 48.0
#: An order enters only with at least this fraction of the strongest order's power. The
#: K_t ripple scales with the whole torque, not only its mean level: the smooth load along
#: the travel modulates it into sidebands (``n ± 1, n ± 2``) a fraction of a percent of its
#: power, which stand far above a low noise floor but are not orders of their own.
RELATIVE_POWER = 0.01
#: K_t ripple is looked for where the two passes differ: it flips sign with the torque,
#: cogging does not. Per order, ``Q = |z₊ − z₋|²`` (each pass's own harmonic) is, without
#: ripple, exponential about the local noise mean (its median over nearby orders / ln 2);
#: an order is taken when ``Q`` exceeds ``ln(M/α)`` times that mean, ``M`` the orders
#: scanned, so that a unit without ripple shows a false one with probability ``α``.
RIPPLE_FALSE_ALARM = 0.01
#: Orders either side whose median sets an order's local noise mean (the loop's chatter
#: is not white: its floor changes with the order).
RIPPLE_FLOOR_WINDOW = 20


@dataclass(frozen=True, slots=True, kw_only=True)
class HarmonicEstimate:
    """One position harmonic ``A·sin(n·θ + φ)`` of cogging or K_t ripple.

    Attributes
    ----------
    order : int
        ``n``, cycles per revolution of the motor position θ.
    amplitude : float
        ``A``: N·m for cogging, relative (a fraction of K_t) for K_t ripple.
    phase_rad : float
        ``φ``, with θ the motor position (rad, encoder zero).
    amplitude_u : float
        Standard uncertainty of ``amplitude``, in its unit.
    """

    order: int
    amplitude: float  # N·m for cogging, relative for K_t ripple
    phase_rad: float
    amplitude_u: float


@dataclass(frozen=True, slots=True, kw_only=True)
class CoggingResult:
    """Cogging and K_t ripple separated by two constant-velocity passes.

    Attributes
    ----------
    cogging : tuple of HarmonicEstimate
        Cogging harmonics (N·m), one per order found.
    kt_ripple : tuple of HarmonicEstimate
        K_t ripple harmonics (relative) at the same orders.
    cogging_peak : Estimate
        ``cogging_peak_nm``: the largest cogging amplitude (N·m).
    kt_ripple_peak : Estimate
        ``kt_ripple_peak_pct``: the largest K_t ripple amplitude (%).
    torque_levels_nm : tuple of float
        Mean smooth torque of each pass, in the order of the passes (N·m).
    noise_rms_nm : float
        Residual torque RMS of the noisier pass, at least the torque's quantisation
        ``LSB/√12`` (N·m).
    orders_scanned : tuple of int
        ``(min_order, max_order)`` of the order scan.
    """

    cogging: tuple[HarmonicEstimate, ...]
    kt_ripple: tuple[HarmonicEstimate, ...]
    cogging_peak: Estimate  # largest cogging harmonic, N·m
    kt_ripple_peak: Estimate  # largest K_t ripple harmonic, %
    torque_levels_nm: tuple[float, float]
    noise_rms_nm: float
    orders_scanned: tuple[int, int]


def _design(theta: FloatArray, orders: list[int], poly: int, centre: float,
            scale: float) -> FloatArray:
    return np.column_stack(
        [polynomial_columns((theta - centre) / scale, poly), harmonic_columns(theta, orders)]
    )


def _smooth_residual(theta: FloatArray, torque: FloatArray, poly: int, centre: float,
                     scale: float) -> FloatArray:
    design = _design(theta, [], poly, centre, scale)
    coef = np.linalg.lstsq(design, torque, rcond=None)[0]
    return np.asarray(torque - design @ coef, dtype=np.float64)


def check_resolution(torque_nm: FloatArray, *, noise_rms_nm: float, amplitude_nm: float) -> float:
    """Refuse a sub-LSB amplitude when the quantisation is not dithered; returns the LSB.

    With noise well above half a step (σ ≥ LSB/2) the quantisation error is uniform,
    independent of the signal: it adds ``LSB²/12`` of variance and no bias, and averaging
    resolves harmonics far below one step. Without that noise the quantiser is a
    deterministic staircase: an amplitude below one step is lost or distorted.

    Raises
    ------
    IdentificationError
        σ < LSB/2 and ``amplitude_nm`` < LSB.
    """
    lsb = quantisation_step(torque_nm)
    if lsb > 0 and noise_rms_nm < 0.5 * lsb and amplitude_nm < lsb:
        raise IdentificationError(
            f"torque resolution {lsb:.3g} N·m with noise σ = {noise_rms_nm:.3g} N·m (< LSB/2): "
            f"the quantisation is not dithered, so a ripple of {amplitude_nm:.3g} N·m (below "
            "one LSB) cannot be resolved; use a finer torque object or add dither"
        )
    return lsb


@dataclass(frozen=True, slots=True, kw_only=True)
class RippleScan:
    """Orders where the two passes' harmonics differ beyond their noise (K_t ripple).

    Attributes
    ----------
    orders : tuple of int
        The orders taken, strongest first.
    detection_limit_nm : float
        The difference ``|z₊ − z₋|`` (N·m) found with 95 % probability at the noisiest
        order scanned: a ripple ``r`` (relative) shows as ``r·|T̄₊ − T̄₋|``.
    """

    orders: tuple[int, ...]
    detection_limit_nm: float


def ripple_scan(segments: list[Segment], *, taken: list[int], orders: tuple[int, int],
                max_orders: int, false_alarm: float = RIPPLE_FALSE_ALARM) -> RippleScan:
    """K_t ripple orders from the difference of the two passes' harmonics.

    The pursuit's orders (cogging, strong ripple) are first fitted out of each pass with
    their own amplitudes, and they and their next neighbours left out. Then, order by
    order, ``Q = |z₊ − z₋|²`` against the local noise mean, greedily: the strongest
    order above ``ln(M/α)`` times its mean is taken, the orders within three resolutions
    ``2π/travel`` of it (its leakage) left out, and so on (see
    :data:`RIPPLE_FALSE_ALARM`).

    Parameters
    ----------
    segments : list of Segment
        The two passes' residuals about their smooth trend.
    taken : list of int
        Orders the matching pursuit already took.
    orders : (int, int)
        Inclusive range scanned.
    max_orders : int
        At most this many ripple orders.
    false_alarm : float
        ``α``, the probability of a false order on a unit without ripple.

    Returns
    -------
    RippleScan
    """
    left = []
    for segment in segments:
        columns = harmonic_columns(segment.position_rad, taken)
        residual = segment.residual
        if taken:
            residual = residual - columns @ np.linalg.lstsq(columns, residual, rcond=None)[0]
        left.append(Segment(residual=residual, position_rad=segment.position_rad))
    ks, z = segment_amplitudes(left, orders=orders)
    if ks.size == 0:
        return RippleScan(orders=(), detection_limit_nm=math.inf)
    q = np.abs(z[0] - z[1]) ** 2
    travel = min(float(np.ptp(s.position_rad)) for s in segments)
    reach = 3 * 2 * math.pi / max(travel, 1e-12)
    # the taken orders are fitted out of each pass exactly, leakage included; what they
    # leave in the difference is at their own order (the loop's acceleration flips with
    # the direction) and the next
    free = np.ones(ks.size, dtype=bool)
    for k in taken:
        free &= np.abs(ks - k) > 1
    if np.count_nonzero(free) < 10:
        return RippleScan(orders=(), detection_limit_nm=math.inf)
    mean = np.array([_local_median(q, free & (np.abs(ks - k) <= RIPPLE_FLOOR_WINDOW), free)
                     for k in ks]) / math.log(2)
    threshold = math.log(np.count_nonzero(free) / false_alarm)
    # |Δz| found 95 % of the time: the threshold's amplitude plus 1.645 noise SDs of |Δz|;
    # a ripple may sit at any order, so the bound is the worst order's (the lowest orders,
    # near the smooth trend, are the noisiest)
    local = np.sqrt(threshold * mean) + 1.645 * np.sqrt(mean / 2)
    limit = float(np.max(local[free]))
    chosen: list[int] = []
    candidate = free & (q > threshold * mean)
    while len(chosen) < max_orders and np.any(candidate):
        best = int(np.argmax(np.where(candidate, q / mean, -np.inf)))
        chosen.append(int(ks[best]))
        candidate &= np.abs(ks - ks[best]) > reach
    return RippleScan(orders=tuple(chosen), detection_limit_nm=limit)


def _local_median(q: FloatArray, near: NDArray[np.bool_], free: NDArray[np.bool_]) -> float:
    """Median of ``q`` over the nearby free orders, or over every free one when too few."""
    return float(np.median(q[near] if np.count_nonzero(near) >= 10 else q[free]))


def harmonic_variances(design: FloatArray, residual: FloatArray, theta: FloatArray,
                       orders: list[int], *, scanned: tuple[int, int],
                       floor: float) -> FloatArray:
    """Variance of each fitted order's cos and sin coefficients (N·m²), from the
    residual's own harmonics at the orders nearby.

    The residual is not white (the velocity loop's chatter on the encoder's steps, its
    lag, coloured torque noise), so neither its overall variance nor an autocorrelation-
    consistent covariance (whose lag window smooths the spectrum towards zero frequency:
    1.5 × too wide in variance over simulated elevation units) gives an order's error.
    The residual's own component at a free order ``k`` (the columns ``cos kθ, sin kθ``
    added to the fit) is ``eᵀP_k e ~ σ²(k)·χ²(2)`` about the local level ``σ²(k)``; the
    median over the free orders within :data:`RIPPLE_FLOOR_WINDOW` of each fitted order
    (or over every free one when fewer than 10), divided by ``2 ln 2``, is that order's
    level. Orders within two of a fitted one (its leakage, the K_t ripple's sidebands) are
    not free. The level, never below ``floor``, times the coefficient's cofactor
    ``[(XᵀX)⁻¹]_jj`` is its variance.

    Parameters
    ----------
    design : ndarray, shape (n, p)
        The fit's columns (smooth trend, then the fitted orders).
    residual : ndarray, shape (n,)
        Its residual.
    theta : ndarray, shape (n,)
        The position (rad).
    orders : list of int
        The fitted orders, in the design's order.
    scanned : (int, int)
        The order range the free orders are taken from.
    floor : float
        The least level per sample (N·m²): what dithered quantisation alone leaves.

    Returns
    -------
    ndarray, shape (2·len(orders),)
        In the design's order of the harmonic columns (cos, sin of each order).
    """
    gram_inv = np.linalg.inv(design.T @ design)
    cofactor = np.diag(gram_inv)[design.shape[1] - 2 * len(orders):]
    ks = np.arange(scanned[0], scanned[1] + 1)
    free = np.ones(ks.size, dtype=bool)
    for k in orders:
        free &= np.abs(ks - k) > 2
    candidates = ks[free]
    if candidates.size == 0:
        overall = float(residual @ residual) / max(len(residual) - 1, 1)
        return max(overall, floor) * cofactor
    # cos kθ and sin kθ of the candidate orders, each from the one before by the angle-sum
    # rule (no trig per order)
    angle = np.asarray(theta, dtype=np.float64)
    steps = {int(d): (np.cos(d * angle), np.sin(d * angle))
             for d in np.unique(np.diff(candidates))}
    cos = np.empty((candidates.size, len(angle)))
    sin = np.empty_like(cos)
    cos[0], sin[0] = np.cos(candidates[0] * angle), np.sin(candidates[0] * angle)
    for j in range(1, candidates.size):
        c_d, s_d = steps[int(candidates[j] - candidates[j - 1])]
        cos[j] = cos[j - 1] * c_d - sin[j - 1] * s_d
        sin[j] = sin[j - 1] * c_d + cos[j - 1] * s_d
    cos, sin = cos.T, sin.T
    # each pair's Gram with the fit's columns taken out: CᵀC − (XᵀC)ᵀ(XᵀX)⁻¹(XᵀC)
    xc, xs = design.T @ cos, design.T @ sin
    c11 = np.einsum("ij,ij->j", cos, cos) - np.einsum("ij,ij->j", xc, gram_inv @ xc)
    c12 = np.einsum("ij,ij->j", cos, sin) - np.einsum("ij,ij->j", xc, gram_inv @ xs)
    c22 = np.einsum("ij,ij->j", sin, sin) - np.einsum("ij,ij->j", xs, gram_inv @ xs)
    b1, b2 = residual @ cos, residual @ sin  # the residual is orthogonal to the design
    det = c11 * c22 - c12**2
    quadratic = (c22 * b1**2 - 2 * c12 * b1 * b2 + c11 * b2**2) / det  # eᵀP_k e
    every = np.ones(candidates.size, dtype=bool)
    levels = np.array([_local_median(quadratic, np.abs(candidates - k) <= RIPPLE_FLOOR_WINDOW,
                                     every) for k in orders]) / (2 * math.log(2))
    return np.maximum(np.repeat(levels, 2), floor) * cofactor


def _ripple_peak(ripple: tuple[HarmonicEstimate, ...], *, detection_limit: float) -> Estimate:
    """``kt_ripple_peak_pct``: the largest significant ripple harmonic or, when none stands
    out of its noise, a value known only to lie between 0 and the detection limit
    (rectangular: ``D/2 ± D/√12``)."""
    significance = math.sqrt(2 * math.log(max(len(ripple), 1) / RIPPLE_FALSE_ALARM))
    found = [h for h in ripple if h.amplitude > significance * h.amplitude_u]
    if found:
        top = max(found, key=lambda h: h.amplitude)
        return Estimate(name="kt_ripple_peak_pct", value=100 * top.amplitude,
                        standard_uncertainty=100 * top.amplitude_u, unit="%")
    limit_pct = 100 * detection_limit
    bound = Component(source=f"no K_t ripple above the detection limit {limit_pct:.2g} % "
                             "(rectangular between 0 and it)",
                      kind="B", standard_uncertainty=limit_pct / math.sqrt(12), unit="%")
    return Estimate(name="kt_ripple_peak_pct", value=limit_pct / 2,
                    standard_uncertainty=bound.standard_uncertainty, unit="%", budget=(bound,))


def identify_cogging(
    passes: list[tuple[FloatArray, FloatArray, FloatArray]],
    *,
    inertia_kg_m2: float,
    min_order: int,
    max_order: int,
    prominence: float = PROMINENCE,
    relative_power: float = RELATIVE_POWER,
    poly: int = 6,
    max_orders: int = 8,
) -> CoggingResult:
    """Cogging and K_t ripple harmonics from two constant-velocity passes
    ``(time_s, θ, T_cmd)`` at different torque levels (e.g. up and down the travel).

    The velocity loop does not reject cogging completely: the rest accelerates the inertia,
    with a phase that flips with the direction and would pass for K_t ripple. Each order's
    position ripple ``δθ_n`` (harmonic fit of θ about its linear trend in time) gives the
    acceleration ``α_n = −(n·v)²·δθ_n``; ``J·α_n`` is removed from the torque harmonic.

    Parameters
    ----------
    passes : list of (time_s, position_rad, torque_nm)
        The two constant-velocity passes.
    inertia_kg_m2 : float
        J for the acceleration correction (measured, or the declared nominal).
    min_order, max_order : int
        The orders per revolution scanned.
    prominence : float
        An order is taken when its power, summed over the passes, is at least this many
        times the median power (see :data:`PROMINENCE` and
        :class:`~hil.identify.orders.PursuitLimits`) ...
    relative_power : float
        ... and at least this fraction of the strongest order's power (see
        :data:`RELATIVE_POWER`).
    poly : int
        Order of the smooth (friction, gravity, cable) trend removed against position.
    max_orders : int
        At most this many orders are kept.

    Returns
    -------
    CoggingResult
        Cogging and K_t-ripple harmonics, their peaks as estimates, the torque levels and
        the noise.

    Raises
    ------
    IdentificationError
        Not two passes, torque levels too close to separate ripple from cogging, no
        harmonic above the noise, or a cogging amplitude below an undithered torque
        resolution (:func:`check_resolution`).
    """
    if len(passes) != 2:
        raise IdentificationError(f"need two passes at different torque levels, got {len(passes)}")
    angle_torque = [(theta, torque) for _, theta, torque in passes]
    lo = min(float(t.min()) for t, _ in angle_torque)
    hi = max(float(t.max()) for t, _ in angle_torque)
    centre, scale = (lo + hi) / 2, (hi - lo) / 2
    segments = [Segment(residual=_smooth_residual(theta, torque, poly, centre, scale),
                        position_rad=theta) for theta, torque in angle_torque]
    limits = PursuitLimits(prominence=prominence, relative_power=relative_power,
                           max_orders=max_orders)
    taken = matching_pursuit(segments, orders=(min_order, max_order), limits=limits)
    scan = ripple_scan(segments, taken=taken, orders=(min_order, max_order),
                       max_orders=max_orders)
    orders = sorted({*taken, *scan.orders})
    smooth_sigma = max(float(np.std(s.residual)) for s in segments)
    all_torque = np.concatenate([torque for _, torque in angle_torque])
    if not orders:
        check_resolution(all_torque, noise_rms_nm=smooth_sigma, amplitude_nm=0.0)
        n_min = min(len(t) for t, _ in angle_torque)
        # median of the summed power σ²·χ²(4) of two passes, as an RMS amplitude
        white_floor = 1.83 * smooth_sigma / math.sqrt(n_min)
        raise IdentificationError(
            f"no position harmonic of order {min_order}-{max_order} stands "
            f"{prominence:g}× above the floor in power (torque noise σ = {smooth_sigma:.3g} "
            f"N·m over {n_min} samples a pass: white-noise floor ≈ {white_floor:.2g} N·m, "
            "RMS over the passes)"
        )
    lsb = quantisation_step(all_torque)
    order_array = np.array(orders, dtype=np.float64)
    z, zu, levels, noise = [], [], [], []
    for time_s, theta, torque in passes:
        design = _design(theta, orders, poly, centre, scale)
        coef, *_ = np.linalg.lstsq(design, torque, rcond=None)
        residual = torque - design @ coef
        dof = len(torque) - design.shape[1]
        # dithered quantisation is in the residual already; never claim less than it
        sigma2 = max(float(residual @ residual) / dof, lsb**2 / 12)
        # the torque left after the fit is mostly the velocity loop's chatter on the
        # encoder's steps, not white: each order's coefficients take the residual's own
        # level at nearby orders (:func:`harmonic_variances`), never below what
        # dithered quantisation alone leaves (LSB²/12 white)
        var = harmonic_variances(design, residual, theta, orders,
                                 scanned=(min_order, max_order), floor=lsb**2 / 12)
        harmonic = coef[poly + 1:]
        # position ripple about the trend, in the same θ-harmonic basis
        trend = np.polyfit(time_s, theta, 1)
        ripple_design = _design(theta, orders, 2, centre, scale)
        pos = np.linalg.lstsq(ripple_design, theta - np.polyval(trend, time_s), rcond=None)[0]
        accel = -((order_array * trend[0]) ** 2)
        harmonic = harmonic - inertia_kg_m2 * np.repeat(accel, 2) * pos[3:]
        # α·cos + β·sin = A·sin(nθ + φ):  z = β + iα
        z.append(harmonic[1::2] + 1j * harmonic[0::2])
        zu.append(np.sqrt((var[0::2] + var[1::2]) / 2))
        smooth = design[:, :poly + 1] @ coef[:poly + 1]
        levels.append(float(smooth.mean()))
        noise.append(math.sqrt(sigma2))
    spread = levels[0] - levels[1]
    if abs(spread) < 5 * max(noise) / math.sqrt(min(len(t) for t, _ in angle_torque)) or abs(
            spread) < 1e-4:
        raise IdentificationError(
            f"torque levels {levels[0]:.4g} and {levels[1]:.4g} N·m are too close to separate "
            "K_t ripple from cogging"
        )
    ripple = -(z[0] - z[1]) / spread
    ripple_u = np.hypot(zu[0], zu[1]) / abs(spread)
    cogging = z[0] + levels[0] * ripple
    # cogging = z₀·(1 − a) + z₁·a with a = T̄₊/(T̄₊ − T̄₋): the two passes' independent
    # errors, not z₀'s and the ripple's as if they were independent (1.7 × too wide)
    share = levels[0] / spread
    cogging_u = np.hypot((1 - share) * zu[0], share * zu[1])
    cog = tuple(HarmonicEstimate(order=n, amplitude=float(abs(c)), phase_rad=float(np.angle(c)),
                                 amplitude_u=float(u))
                for n, c, u in zip(orders, cogging, cogging_u, strict=True))
    rip = tuple(HarmonicEstimate(order=n, amplitude=float(abs(r)), phase_rad=float(np.angle(r)),
                                 amplitude_u=float(u))
                for n, r, u in zip(orders, ripple, ripple_u, strict=True))
    top_cog = max(cog, key=lambda h: h.amplitude)
    check_resolution(all_torque, noise_rms_nm=float(max(noise)), amplitude_nm=top_cog.amplitude)
    return CoggingResult(
        cogging=cog,
        kt_ripple=rip,
        cogging_peak=Estimate(name="cogging_peak_nm", value=top_cog.amplitude,
                              standard_uncertainty=top_cog.amplitude_u, unit="N·m"),
        kt_ripple_peak=_ripple_peak(rip, detection_limit=scan.detection_limit_nm / abs(spread)),
        torque_levels_nm=(levels[0], levels[1]),
        noise_rms_nm=float(max(noise)),
        orders_scanned=(min_order, max_order),
    )


def compensation_table(result: CoggingResult, *, significance: float = 3.0) -> dict[str, object]:
    """The documented JSON compensation table (module docstring).

    Parameters
    ----------
    result : CoggingResult
        The identified harmonics.
    significance : float
        A harmonic is kept when its amplitude exceeds this many standard uncertainties.

    Returns
    -------
    dict
        ``format``, ``model``, ``angle``, and the kept ``cogging`` (N·m) and ``kt_ripple``
        (relative) harmonics as lists of dicts, ready for ``json.dump``.
    """
    return {
        "format": COMPENSATION_FORMAT,
        "model": "T_ff(θ) = Σ cogging A_n·sin(n·θ + φ_n);  "
                 "K_t(θ) = K_t·(1 + Σ kt_ripple a_n·sin(n·θ + ψ_n))",
        "angle": "motor position in rad, encoder zero",
        "cogging": [{"order": h.order, "amplitude_nm": h.amplitude, "phase_rad": h.phase_rad,
                     "amplitude_u_nm": h.amplitude_u}
                    for h in result.cogging if h.amplitude > significance * h.amplitude_u],
        "kt_ripple": [{"order": h.order, "amplitude": h.amplitude, "phase_rad": h.phase_rad,
                       "amplitude_u": h.amplitude_u}
                      for h in result.kt_ripple if h.amplitude > significance * h.amplitude_u],
    }
