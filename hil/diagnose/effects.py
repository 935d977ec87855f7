"""The effect library: how each candidate extends a model (columns + 1-D searches).

Each ``propose_*`` function takes the current model fitted on the training rows and
returns the extended model with its nonlinear parameter(s) already chosen on the
training rows (separable least squares: for a fixed nonlinear parameter the model is
linear; the parameter is found by a grid search refined with a bounded scalar search).
It returns ``None`` when the effect does not apply (already in the model, wrong axis kind,
nothing periodic found, ...). Judging the gain is :mod:`hil.diagnose.select`'s job.
"""

from __future__ import annotations

import hashlib
import logging
import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar
from scipy.signal import bilinear, lfilter

from hil.diagnose import ripple
from hil.diagnose.lag import search_lag
from hil.diagnose.model import Designer, Fit, IndexArray, Model, Term, friction_direction
from hil.diagnose.signals import Signals
from hil.identify.gravity_cable import dahl_state
from hil.identify.orders import PursuitLimits, Segment, matching_pursuit, order_range

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

EFFECTS = (
    "offset",
    "asymmetric_friction",
    "stribeck",
    "cogging",
    "kt_ripple",
    "gravity",
    "cable_spring",
    "current_lag",
    "two_mass",
)
#: When the matching pursuit (:func:`hil.identify.orders.matching_pursuit`) takes an order
#: of cogging or K_t ripple: power ≥ 4.5 × the periodogram's median away from the order's
#: leakage, effective χ²(2) above the Bonferroni threshold for 200 orders at 1 %, at least
#: 2 % of the first order's power; six orders at most.
ORDER_LIMITS = PursuitLimits(
    prominence=4.5, min_chi2=-2.0 * math.log(0.01 / 200), relative_power=0.02, max_orders=6
)
#: Effects whose searched parameters are kept from the round they were first searched in
#: (the harmonic orders are searched again: the weight of K_t ripple is the current model;
#: so are the lag and its lead, which an effect missing from the model biases, and the
#: spring's hysteresis loop: one kept from a round before the lag, there soaking up the
#: friction's switching, went negative beside it and the spring was rejected as implausible).
REUSABLE = frozenset({"stribeck", "two_mass"})
ROTARY_ONLY = frozenset({"cogging", "kt_ripple", "gravity"})
#: BIC margin a Dahl loop must win by over the spring alone ("very strong", Kass–Raftery):
#: the loop state is close to sgn(ω) and otherwise soaks up friction misfit.
LOOP_EVIDENCE_BIC = 10.0
#: Dahl hysteresis: angle over which the cable's friction loop saturates (rad).
HYSTERESIS_ANGLES_RAD = (0.005, 0.02, 0.08)
#: Damping ratios searched for a shaft: up to well-damped filters, which a resonance is not
#: (see :data:`hil.diagnose.select.MAX_RESONANCE_DAMPING`), so that a smooth fall of the
#: effective inertia with frequency is fitted as one, not as the broadest resonance offered.
TWO_MASS_DAMPING = (0.02, 0.05, 0.1, 0.2, 0.4, 0.7)
#: A resonance is resolved when it lies below this fraction of the analysis bandwidth.
TWO_MASS_BAND = 0.6
#: Lowest antiresonance searched, as a fraction of the analysis bandwidth (10 Hz at the
#: default 250 Hz): below it a shaft filter sits on the slow test signals (a 2 Hz sine),
#: where a filter at the sine's frequency fits any misfit in phase or quadrature with it.
TWO_MASS_LOW = 0.04


class Context:
    """The training data and the current model fitted on it.

    Parameters
    ----------
    designer : Designer
    signals : Signals
    rows : ndarray of intp
        The training rows.
    current : Fit
        The current model on them.
    counts_per_rev : int, optional
        Encoder counts per revolution (bounds the harmonic orders searched).
    memory : dict of str to Model, optional
        Models proposed in earlier rounds, by effect; :func:`propose` adds to it.
    """

    def __init__(self, *, designer: Designer, signals: Signals, rows: IndexArray, current: Fit,
                 counts_per_rev: int | None = None,
                 memory: dict[str, Model] | None = None) -> None:
        self.designer = designer
        #: models proposed in earlier rounds: their searched parameters are reused
        self.memory: dict[str, Model] = {} if memory is None else memory
        self.signals = signals
        self.rows = rows
        self.current = current
        self.counts_per_rev = counts_per_rev
        self._basis: tuple[FloatArray, FloatArray] | None = None

    def basis(self) -> tuple[FloatArray, FloatArray]:
        """Orthonormal basis of the current design (training rows) and its residual.

        Returns
        -------
        q, residual : ndarray
            ``Q`` of the design's QR decomposition, and the filtered effort minus its
            projection onto ``Q`` (computed once, then cached).
        """
        if self._basis is None:
            matrix = self.designer.design(self.current.model, self.signals, self.rows)
            q, _ = np.linalg.qr(matrix)
            target = self.signals.effort_filtered[self.rows]
            self._basis = (q, target - q @ (q.T @ target))
        return self._basis


def propose(effect: str, ctx: Context) -> Model | None:
    """The current model extended with ``effect`` (searched on the training rows).

    Parameters
    ----------
    effect : str
        One of :data:`EFFECTS`.
    ctx : Context
        The training data and current model; the proposal is stored in its ``memory``.

    Returns
    -------
    Model or None
        ``None`` when the current model has ``effect``, when ``effect`` is rotary-only on
        a linear axis, or when it does not apply. Effects in :data:`REUSABLE` proposed in
        an earlier round keep the parameters searched then.

    Raises
    ------
    KeyError
        ``effect`` is not in :data:`EFFECTS`.
    """
    if ctx.current.model.has(effect):
        return None
    if effect in ROTARY_ONLY and ctx.signals.axis_kind != "rotary":
        return None
    remembered = ctx.memory.get(effect)
    if remembered is not None and effect in REUSABLE:
        return _reuse(effect, remembered, ctx.current.model)
    model = _PROPOSERS[effect](ctx)
    if model is not None:
        ctx.memory[effect] = model
    return model


def _reuse(effect: str, earlier: Model, current: Model) -> Model:
    """``current`` extended with what ``earlier`` added for ``effect`` (no new search)."""
    added = tuple(term for term in earlier.terms if term.effect == effect)
    if effect == "cable_spring":  # its constant only where the model has none (else singular)
        angle = added[0].nonlinear.get("hysteresis_angle_rad") if added else None
        return _extend(current, _cable_term(angle, not _has_constant(current)))
    return _extend(current, *added)


def _extend(model: Model, *terms: Term) -> Model:
    return replace(model, terms=model.terms + terms)


CONSTANT_LABELS = frozenset({"offset", "cable_constant", "coulomb_neg_delta"})


def _has_constant(model: Model) -> bool:
    return any(CONSTANT_LABELS & set(term.labels) for term in model.terms)


def _train_rss(ctx: Context, model: Model) -> float:
    """Training RSS of ``model``; fast when it only adds terms to the current model."""
    current = ctx.current.model
    if (
        model.lag_s == current.lag_s
        and model.shift_s == current.shift_s
        and model.friction_delay == current.friction_delay
        and model.terms[: len(current.terms)] == current.terms
    ):
        added = replace(model, terms=model.terms[len(current.terms) :])
        block = ctx.designer.design(added, ctx.signals, ctx.rows)
        q, residual = ctx.basis()
        block = block - q @ (q.T @ block)
        coef, *_ = np.linalg.lstsq(block, residual, rcond=None)
        left = residual - block @ coef
        return float(left @ left)
    matrix = ctx.designer.design(model, ctx.signals, ctx.rows)
    target = ctx.signals.effort_filtered[ctx.rows]
    scale = np.sqrt(np.sum(matrix**2, axis=0))
    scale[scale == 0] = 1.0
    coef, *_ = np.linalg.lstsq(matrix / scale, target, rcond=None)
    residual = target - (matrix / scale) @ coef
    return float(residual @ residual)


def _search(
    ctx: Context, make: Callable[[float], Model], grid: FloatArray, *, log_scale: bool = True
) -> tuple[float, Model]:
    """Minimise training RSS over one nonlinear parameter: grid, then bounded refinement."""
    costs = [_train_rss(ctx, make(float(value))) for value in grid]
    best = int(np.argmin(costs))
    low = grid[max(best - 1, 0)]
    high = grid[min(best + 1, len(grid) - 1)]
    if high > low:
        to_x: Callable[[float], float] = math.log if log_scale else float
        from_x: Callable[[float], float] = math.exp if log_scale else float
        result = minimize_scalar(
            lambda x: _train_rss(ctx, make(from_x(x))),
            bounds=(to_x(float(low)), to_x(float(high))),
            method="bounded",
            options={"xatol": 1e-2},
        )
        value = from_x(float(result.x))
        if float(result.fun) <= costs[best]:
            return value, make(value)
    value = float(grid[best])
    return value, make(value)


# -- linear-in-parameters effects ----------------------------------------------------------
#: Offset and direction-dependent friction need motion in both directions, each in at
#: least this fraction of the moving training samples (else they equal Coulomb friction).
MIN_DIRECTION_FRACTION = 0.10


def both_directions(ctx: Context) -> bool:
    """Whether the training rows move both ways enough to tell a constant from friction.

    Parameters
    ----------
    ctx : Context

    Returns
    -------
    bool
        Each direction holds at least :data:`MIN_DIRECTION_FRACTION` of the moving
        training rows (see :func:`hil.diagnose.model.friction_direction`).
    """
    direction = friction_direction(ctx.signals)[ctx.rows]
    moving = np.count_nonzero(direction)
    if moving == 0:
        return False
    share = min(np.count_nonzero(direction > 0), np.count_nonzero(direction < 0)) / moving
    return bool(share >= MIN_DIRECTION_FRACTION)


def _offset(ctx: Context) -> Model | None:
    if _has_constant(ctx.current.model) or not both_directions(ctx):
        return None
    term = Term(effect="offset", labels=("offset",), key="offset",
                build=lambda s: np.ones(len(s)))
    return _extend(ctx.current.model, term)


def _negative(s: Signals) -> FloatArray:
    return (friction_direction(s) < 0).astype(np.float64)


def _asymmetric(ctx: Context) -> Model | None:
    """Direction-dependent viscous and Coulomb friction.

    While the axis moves, a Coulomb difference between the directions is a constant
    (``ΔT_c·1(ω<0) = ΔT_c/2 − ΔT_c/2·sgn ω``): it is modelled as the constant ``−ΔT_c/2``
    (with ``T_c`` the mean of the two directions), and with a constant already in the
    model only the viscous difference is added.
    """
    if not both_directions(ctx):
        return None
    # the velocity is already low-passed (like the base viscous column): not filtered again
    viscous = Term(effect="asymmetric_friction", labels=("viscous_neg_delta",),
                   key="asymmetric:viscous", filtered=True, friction=True,
                   build=lambda s: s.velocity * _negative(s))
    if _has_constant(ctx.current.model):
        return _extend(ctx.current.model, viscous)
    # the Coulomb difference as a constant −ΔT_c/2 (= an offset): the same as −ΔT_c·1(ω<0)
    # while moving, and a constant, like any torque, at standstill too; the offset is then
    # the same model without the viscous difference (one parameter fewer)
    coulomb = Term(effect="asymmetric_friction", labels=("coulomb_neg_delta",),
                   key="asymmetric:constant", filtered=True,
                   build=lambda s: np.full(len(s), -0.5))
    return _extend(ctx.current.model, viscous, coulomb)


def _gravity(ctx: Context) -> Model | None:
    term = Term(
        effect="gravity",
        labels=("gravity_cos", "gravity_sin"),
        key="gravity",
        build=lambda s: np.column_stack((np.cos(s.position), np.sin(s.position))),
    )
    return _extend(ctx.current.model, term)


def _cable_term(angle: float | None, constant: bool) -> Term:
    """Spring ``k·θ`` (+ constant), with a Dahl hysteresis loop when ``angle`` is given."""
    labels: tuple[str, ...] = ("cable_stiffness",)
    if angle is not None:
        labels += ("cable_hysteresis",)
    if constant:
        labels += ("cable_constant",)

    def build(s: Signals) -> FloatArray:
        columns = [s.position]
        if angle is not None:
            columns.append(dahl_state(np.ascontiguousarray(s.position), angle))
        if constant:
            columns.append(np.ones(len(s)))
        return np.column_stack(columns)

    nonlinear = {} if angle is None else {"hysteresis_angle_rad": angle}
    return Term(effect="cable_spring", labels=labels, key=f"cable:{angle}:{constant}",
                build=build, nonlinear=nonlinear)


def _cable(ctx: Context) -> Model | None:
    """The spring alone, or with the hysteresis loop that fits best, by training BIC.

    A loop must dissipate (positive half-width); the Dahl state is close to sgn(ω), so
    its width is only credible when it beats the spring alone on BIC.
    """
    constant = not _has_constant(ctx.current.model)
    best = _extend(ctx.current.model, _cable_term(None, constant))
    best_bic = ctx.designer.fit(best, ctx.signals, ctx.rows).bic
    for angle in HYSTERESIS_ANGLES_RAD:
        model = _extend(ctx.current.model, _cable_term(angle, constant))
        fit = ctx.designer.fit(model, ctx.signals, ctx.rows)
        if fit.coef("cable_hysteresis") > 0 and fit.bic < best_bic - LOOP_EVIDENCE_BIC:
            best, best_bic = model, fit.bic
    return best


# -- one nonlinear parameter -------------------------------------------------------------
def stribeck_term(velocity_scale: float) -> Term:
    """The Stribeck column ``exp(−(ω/v_s)²)·sgn(ω)``, coefficient ``stribeck_delta``.

    Parameters
    ----------
    velocity_scale : float
        ``v_s`` (rad/s, or m/s on a linear axis).

    Returns
    -------
    Term
        Effect ``"stribeck"``; ``v_s`` is its nonlinear ``stribeck_velocity``.
    """
    def build(s: Signals) -> FloatArray:
        ratio = s.velocity / velocity_scale
        return np.exp(-(ratio**2)) * friction_direction(s)

    return Term(effect="stribeck", labels=("stribeck_delta",), key=f"stribeck:{velocity_scale:.9g}",
                build=build, nonlinear={"stribeck_velocity": velocity_scale}, friction=True)


def _stribeck(ctx: Context) -> Model | None:
    speed = np.abs(ctx.signals.velocity[ctx.rows])
    top = float(np.percentile(speed, 99))
    moving = speed[speed > 1e-3 * top]
    if moving.size < 50 or top <= 0:
        return None
    low = max(float(np.percentile(moving, 1)), 1e-3 * top)
    grid = np.geomspace(low, 0.5 * top, 24)
    model = ctx.current.model
    _, best = _search(ctx, lambda v: _extend(model, stribeck_term(v)), grid)
    return best


def search_shift(ctx: Context, model: Model) -> Model:
    """Best effort/motion alignment within one sample period (training RSS).

    Parameters
    ----------
    ctx : Context
    model : Model

    Returns
    -------
    Model
        ``model`` with the ``shift_s`` in ``[0, 1/fs]`` that minimises the training RSS
        (a 9-point grid, refined by a bounded search): the drive samples the position
        somewhere within the period over which it holds the effort.
    """
    period = 1.0 / ctx.signals.fs_hz
    grid = np.linspace(0.0, period, 9)
    _, best = _search(ctx, lambda d: replace(model, shift_s=d), grid, log_scale=False)
    return best


def _current_lag(ctx: Context) -> Model | None:
    """τ searched jointly with the effort's lead on the bias-compensated RSS
    (:mod:`hil.diagnose.lag`): at low frequency a first-order lag and a delay look alike,
    at high frequency the lag's gain ``√(1 + (ωτ)²)`` tells them apart, where the
    position's quantisation noise would otherwise shorten τ."""
    return search_lag(ctx.designer, ctx.signals, ctx.rows, ctx.current.model)


def two_mass_term(antiresonance_hz: float, damping: float) -> Term:
    """A load on a compliant shaft: the column is load minus motor acceleration.

    The load acceleration is the motor acceleration through
    ``(2ζωs + ω²)/(s² + 2ζωs + ω²)``, ``ω = 2π·antiresonance_hz`` (bilinear transform,
    causal, per segment); the coefficient is ``load_inertia``.

    Parameters
    ----------
    antiresonance_hz : float
    damping : float
        Damping ratio ζ.

    Returns
    -------
    Term
        Effect ``"two_mass"``, nonlinear ``antiresonance_hz`` and ``damping_ratio``.
    """
    omega = 2 * math.pi * antiresonance_hz

    def build(s: Signals) -> FloatArray:
        # load acceleration from motor acceleration through the shaft: (2ζωs + ω²)/(s² + 2ζωs + ω²)
        num, den = bilinear([2 * damping * omega, omega**2], [1.0, 2 * damping * omega, omega**2],
                            fs=s.fs_hz)
        out = np.zeros(len(s))
        for start, stop in s.segments:
            segment = s.acceleration[start:stop]
            out[start:stop] = lfilter(num, den, segment) - segment
        return out

    return Term(effect="two_mass", labels=("load_inertia",), filtered=True,
                key=f"two_mass:{antiresonance_hz:.9g}:{damping:g}", build=build,
                nonlinear={"antiresonance_hz": antiresonance_hz, "damping_ratio": damping})


def _two_mass(ctx: Context) -> Model | None:
    top = TWO_MASS_BAND * ctx.signals.cutoff_hz
    low = max(1.0, TWO_MASS_LOW * ctx.signals.cutoff_hz)
    if top <= 2.0 * low:
        return None
    grid = np.geomspace(low, top, 24)
    model = ctx.current.model
    costs = [
        (_train_rss(ctx, _extend(model, two_mass_term(float(f), d))), d)
        for d in TWO_MASS_DAMPING
        for f in grid
    ]
    damping = min(costs)[1]
    frequency, _ = _search(ctx, lambda f: _extend(model, two_mass_term(f, damping)), grid)
    # ζ refined between its grid neighbours at that frequency: beside a 3.7 ms lag and a load
    # of 85 % a true ζ of 0.03 fitted at the grid's 0.05 put τ −24 % (its interval missing)
    damping, _ = _search(ctx, lambda d: _extend(model, two_mass_term(frequency, d)),
                         np.array(TWO_MASS_DAMPING))
    _, best = _search(ctx, lambda f: _extend(model, two_mass_term(f, damping)),
                      np.geomspace(frequency / 1.2, frequency * 1.2, 5))
    return best


# -- harmonics of the angle ----------------------------------------------------------------
def harmonic_term(effect: str, orders: tuple[int, ...],
                  weight: Callable[[Signals], FloatArray] | None, key: str) -> Term:
    """Harmonics of the angle: columns ``w·sin(kθ)``, ``w·cos(kθ)`` for each order ``k``.

    Parameters
    ----------
    effect : str
        ``"cogging"`` (labels ``cog_sin{k}``, ``cog_cos{k}``), else ``kt_sin{k}``,
        ``kt_cos{k}``.
    orders : tuple of int
        Periods per revolution; each counts as a searched parameter.
    weight : callable or None
        ``Signals -> ndarray`` giving ``w`` (for K_t ripple the predicted effort);
        ``None`` for ``w = 1``.
    key : str
        Tells weights apart in the term's cache key.

    Returns
    -------
    Term
    """
    prefix = "cog" if effect == "cogging" else "kt"
    labels = tuple(f"{prefix}_{part}{k}" for k in orders for part in ("sin", "cos"))

    def build(s: Signals) -> FloatArray:
        w = np.ones(len(s)) if weight is None else weight(s)
        columns: list[FloatArray] = []
        for k in orders:
            columns.extend((w * np.sin(k * s.position), w * np.cos(k * s.position)))
        return np.column_stack(columns)

    return Term(effect=effect, labels=labels, key=f"{effect}:{orders}:{key}", build=build,
                extra_params=len(orders))


def _harmonic(ctx: Context, effect: str) -> Model | None:
    designer, signals, rows = ctx.designer, ctx.signals, ctx.rows
    prediction_fit = ctx.current
    weight: Callable[[Signals], FloatArray] | None = None
    residual = signals.effort_filtered - designer.predict(ctx.current, signals)
    weight_all = np.ones(len(signals))
    if effect == "kt_ripple":
        # the drive's torque is what the lagged current makes of the load, (1 + τs)·T/(1 + r):
        # the weight is the load T (the model without its lead); the term is lagged itself
        load_fit = replace(prediction_fit, model=replace(prediction_fit.model, lag_s=0.0))

        def weight_fn(s: Signals) -> FloatArray:
            return designer.predict(load_fit, s)

        weight = weight_fn
        weight_all = weight_fn(signals)
    residual = residual[rows]
    orders = order_range(signals.position[rows], ctx.counts_per_rev)
    # weighted least squares for the order search: where the model misses most (a chirp,
    # large torque at one angle) every order's column is a constant that soaks up the
    # misfit and lifts the whole periodogram; each row counts by its block's misfit
    scale = local_scale(residual, rows, signals.fs_hz)
    segment = Segment(residual=residual / scale, position_rad=signals.position[rows],
                      weight=weight_all[rows] / scale)
    found = matching_pursuit([segment], orders=orders, limits=ORDER_LIMITS,
                             independence=min(1.0, signals.independence * signals.decimation))
    if not found:
        return None
    key = f"{id(prediction_fit)}" if effect == "kt_ripple" else "1"
    refined = _refine_orders(ctx, effect, tuple(found), weight, key)
    if not refined:
        return None
    return _extend(ctx.current.model, harmonic_term(effect, refined, weight, key))


def reweighted(designer: Designer, fit: Fit, signals: Signals, rows: IndexArray) -> Fit:
    """``fit`` with its K_t ripple's weight rebuilt from ``fit``'s own load, refitted on ``rows``.

    The ripple's weight is the load predicted when it was proposed: by a model fitted
    without the ripple (whose coefficients take up part of it) and without the effects
    named later. The load of the joint model (its other terms with their joint
    coefficients, no lead) is the torque the ripple modulates; with it the depth's error
    over the seed-11 ripple pairs fell (two-mass +6.5 % → −1.2 %, beside cogging
    +8.5 % → +1.1 %, beside a lag +11 % → +2.9 %; once is enough: a second pass moves it
    < 0.1 %).

    Parameters
    ----------
    designer : Designer
    fit : Fit
        A model with all the named causes; returned unchanged without a ``kt_ripple`` term.
    signals : Signals
    rows : ndarray of intp
        The rows ``fit`` was fitted on.

    Returns
    -------
    Fit
        The model with the new weight, fitted on ``rows`` (same columns otherwise).
    """
    term = fit.model.term("kt_ripple")
    if term is None:
        return fit
    keep = ~np.isin(fit.model.labels, term.labels)
    others = tuple(t for t in fit.model.terms if t is not term)
    load = replace(fit, model=replace(fit.model, terms=others, lag_s=0.0),
                   coefficients=fit.coefficients[keep],
                   covariance=fit.covariance[np.ix_(keep, keep)])
    # the columns are cached by key: name the weight by what it is made of
    key = hashlib.sha1(repr((load.model.labels, [t.key for t in others], load.model.shift_s,
                             load.coefficients.tolist())).encode()).hexdigest()[:16]

    def weight(s: Signals) -> FloatArray:
        return designer.predict(load, s)

    orders = ripple.orders_of(fit.model)
    model = replace(fit.model, terms=tuple(
        harmonic_term("kt_ripple", orders, weight, f"load:{key}") if t is term else t
        for t in fit.model.terms))
    return designer.fit(model, signals, rows)


#: How far (in orders) the joint fit looks from each order the pursuit took.
ORDER_REFINE_SPAN = 2


def _refine_orders(ctx: Context, effect: str, found: tuple[int, ...],
                   weight: Callable[[Signals], FloatArray] | None, key: str) -> tuple[int, ...]:
    """The pursuit's orders checked in the joint fit.

    The pursuit scores an order on the residual of the current model with the current
    model's coefficients held. Over a travel shorter than a revolution neighbouring
    orders differ little: once the other coefficients re-adjust (the K_t-ripple column is
    a product with the base prediction) the best order can move by one, and one true order
    can be taken as two neighbours (59 and 61 for 60). So each order is moved to the
    neighbour (±:data:`ORDER_REFINE_SPAN`) with the least training RSS; then each order
    whose removal (the others moved again) lowers the training BIC is dropped; finally an
    order whose sine and cosine are not jointly significant (Wald, χ²(2) above the
    pursuit's threshold) is dropped.
    """
    model = ctx.current.model
    designer, signals = ctx.designer, ctx.signals
    if effect == "kt_ripple":  # where its coefficients are estimated (ripple.py)
        # the rows of the strongest order (a weak low one would take every row)
        lowest = max(1, found[0] - ORDER_REFINE_SPAN)
        rows, band = ripple.estimation_rows(signals, ctx.rows,
                                            (lowest, max(found) + ORDER_REFINE_SPAN))
        n_eff = float(rows.size)
        matrix, target = designer.band_limited(model, signals, rows, band)
        q, _ = np.linalg.qr(matrix)
        residual = target - q @ (q.T @ target)

        def design(candidate: Model) -> FloatArray:
            return designer.band_limited(candidate, signals, rows, band)[0]
    else:
        n_eff = ctx.rows.size * min(1.0, signals.independence * signals.decimation)
        q, residual = ctx.basis()

        def design(candidate: Model) -> FloatArray:
            return designer.design(candidate, signals, ctx.rows)
    projected: dict[int, FloatArray] = {}

    def block(k: int) -> FloatArray:
        """Order ``k``'s two columns on the fitted rows, the current design projected out."""
        if k not in projected:
            columns = design(replace(model, terms=(harmonic_term(effect, (k,), weight, key),)))
            projected[k] = columns - q @ (q.T @ columns)
        return projected[k]

    gram: dict[tuple[int, int], FloatArray] = {}
    total = float(residual @ residual)

    def cross(a: int, b: int) -> FloatArray:
        if (a, b) not in gram:
            gram[(a, b)] = block(a).T @ block(b)
            gram[(b, a)] = gram[(a, b)].T
        return gram[(a, b)]

    def rss(orders: tuple[int, ...]) -> float:
        """Training RSS with ``orders`` added (normal equations on the projected blocks)."""
        normal = np.block([[cross(a, b) for b in orders] for a in orders])
        right = np.concatenate([block(k).T @ residual for k in orders])
        try:
            coef = np.linalg.solve(normal, right)
        except np.linalg.LinAlgError:
            return total
        return max(total - float(right @ coef), 0.0)

    def bic(orders: tuple[int, ...], value: float) -> float:
        return n_eff * math.log(max(value, 1e-300) / n_eff) + 3 * len(orders) * math.log(n_eff)

    def moved(orders: tuple[int, ...]) -> tuple[tuple[int, ...], float]:
        current = list(orders)
        best_rss = rss(orders)
        for index in range(len(current)):
            for k in range(current[index] - ORDER_REFINE_SPAN,
                           current[index] + ORDER_REFINE_SPAN + 1):
                if k < 1 or k in current:
                    continue
                trial = (*current[:index], k, *current[index + 1 :])
                value = rss(trial)
                if value < best_rss:
                    best_rss, current = value, list(trial)
        return tuple(current), best_rss

    orders, value = moved(found)
    changed = True
    while changed and len(orders) > 1:
        changed = False
        for index in reversed(range(len(orders))):  # weakest (taken last) first
            trial, trial_rss = moved((*orders[:index], *orders[index + 1 :]))
            if bic(trial, trial_rss) <= bic(orders, value):
                orders, value, changed = trial, trial_rss, True
                break
    extended = _extend(model, harmonic_term(effect, orders, weight, key))
    fit = (ripple.fit_on_sweep(designer, extended, signals, ctx.rows) if effect == "kt_ripple"
           else designer.fit(extended, signals, ctx.rows))
    prefix = "cog" if effect == "cogging" else "kt"
    kept = []
    for k in orders:
        values, covariance = fit.block((f"{prefix}_sin{k}", f"{prefix}_cos{k}"))
        try:
            statistic = float(values @ np.linalg.solve(covariance, values))
        except np.linalg.LinAlgError:
            continue
        if np.isfinite(statistic) and statistic >= ORDER_LIMITS.min_chi2:
            kept.append(k)
    return tuple(kept)


#: Length of the blocks whose residual RMS weights the rows of the order search, s.
SCALE_BLOCK_S = 0.25


def local_scale(residual: FloatArray, rows: IndexArray, fs_hz: float) -> FloatArray:
    """RMS of ``residual`` in the :data:`SCALE_BLOCK_S` block of each row.

    Parameters
    ----------
    residual : ndarray
        On ``rows``.
    rows : ndarray of intp
        Sample indices (their blocks are ``rows // (SCALE_BLOCK_S·fs_hz)``).
    fs_hz : float

    Returns
    -------
    ndarray
        Per row, floored at a tenth of the overall RMS (1 when that is 0).
    """
    block = rows // max(1, round(SCALE_BLOCK_S * fs_hz))
    _, index = np.unique(block, return_inverse=True)
    count = np.bincount(index).astype(np.float64)
    local = np.sqrt(np.bincount(index, weights=residual**2) / count)[index]
    overall = float(np.sqrt(np.mean(residual**2)))
    return np.asarray(np.maximum(local, 0.1 * overall if overall > 0 else 1.0), dtype=np.float64)


_PROPOSERS: dict[str, Callable[[Context], Model | None]] = {
    "offset": _offset,
    "asymmetric_friction": _asymmetric,
    "stribeck": _stribeck,
    "cogging": lambda ctx: _harmonic(ctx, "cogging"),
    "kt_ripple": lambda ctx: _harmonic(ctx, "kt_ripple"),
    "gravity": _gravity,
    "cable_spring": _cable,
    "current_lag": _current_lag,
    "two_mass": _two_mass,
}
