"""The current-loop lag τ and the effort's lead δ, with the encoder's quantisation compensated.

The model ``T_reported = (1 + τs)·model(t + δ)`` is linear in its coefficients for fixed
``(τ, δ)``. At low frequency a first-order lag and a delay look alike, so ``τ`` and ``δ``
trade along a valley of the RSS (``τ + δ/f_s`` nearly constant); only the lag's gain
``√(1 + (ωτ)²)`` at the top of the band tells them apart. There the regressors carry the
position's quantisation noise, differentiated twice (inertia) or three times (the lag's
lead): errors in the regressors shrink the coefficients they multiply, and the lag's lead
most, so the least-squares valley tilts towards a short ``τ`` with a larger ``δ`` (1.19 ms
for 1.5 ms with 2²⁰ counts/rev; 1.44 ms without quantisation and torque noise).

The search therefore minimises a *bias-compensated* RSS (errors-in-variables: the
regressors' noise covariance ``Σ`` is taken off the normal matrix, ``θ = (ΦᵀΦ − Σ)⁻¹Φᵀy``,
``RSS = yᵀy − θᵀΦᵀy``). ``Σ`` comes from re-quantising the position, drawn through its
changes of level and low-passed, with the recording's own step at :data:`QUANT_PHASES`
offsets of the grid: the same slow-motion correlation and fast-motion whiteness as the
encoder's error, through the same filters and derivatives as the regressors. Only the
columns linear in the motion (inertia, viscous friction, a two-mass load) carry it.
Without a quantisation step (continuous or resampled positions) the RSS is the plain one.

Every evaluation uses Gram matrices (``AᵀA``, ``AᵀB``, ``BᵀB`` of the columns ``A`` and
their leads ``B`` at one ``δ``), summed per group of interleaved blocks so that the
delete-a-group jackknife (:func:`jackknife_lag`) re-searches ``(τ, δ)`` without each group
cheaply.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

from hil.diagnose.model import (
    Designer,
    IndexArray,
    Model,
    Term,
    fractional_shift,
    moving_rows,
)
from hil.diagnose.signals import Signals, derivatives

FloatArray = NDArray[np.float64]

#: Offsets of the re-quantisation grid, in steps (their noise covariances are averaged).
QUANT_PHASES = (0.125, 0.375, 0.625, 0.875)
#: Effort/motion alignments tried by the screening search, in sample periods (then refined
#: by a parabola; the 9-point grid gives the same τ within 0.4 % on the xfail run and on
#: example_05, at twice the cost).
SHIFT_GRID = tuple(np.linspace(0.0, 1.0, 5))
#: ... and by the jackknife: on the coarse grid its replicates' parabolas snap alike and
#: under-disperse (20 single lags: 19/20 intervals holding the truth, error/u RMS 1.27,
#: against 20/20, 1.20 on this grid).
JACKKNIFE_SHIFT_GRID = tuple(np.linspace(0.0, 1.0, 9))
#: Base-model columns that are linear in the motion (and so carry the position's noise).
NOISY_KEYS = frozenset({"inertia", "viscous"})
NOISY_EFFECTS = frozenset({"two_mass"})
#: τ searched from half a sample up to this (s) or 100 samples, whichever is shorter.
MAX_LAG_S = 0.05
#: Jackknife blocks, s: each group takes every ``groups``-th block, a part of every
#: experiment (the lag's information lies in the chirp's top octave: deleting one
#: contiguous stretch of it leaves τ and δ unresolved, not less precise).
BLOCK_S = 0.25


@dataclass(frozen=True, slots=True)
class _Grams:
    """Sums over one group of rows at one alignment (``S*``: the noise's covariance)."""

    aa: FloatArray
    ab: FloatArray
    bb: FloatArray
    ay: FloatArray
    by: FloatArray
    yy: float
    saa: FloatArray
    sab: FloatArray
    sbb: FloatArray

    def __add__(self, other: _Grams) -> _Grams:
        return self._combine(other, 1.0)

    def __sub__(self, other: _Grams) -> _Grams:
        return self._combine(other, -1.0)

    def _combine(self, other: _Grams, sign: float) -> _Grams:
        return _Grams(self.aa + sign * other.aa, self.ab + sign * other.ab,
                      self.bb + sign * other.bb, self.ay + sign * other.ay,
                      self.by + sign * other.by, self.yy + sign * other.yy,
                      self.saa + sign * other.saa, self.sab + sign * other.sab,
                      self.sbb + sign * other.sbb)

    def rss(self, lag_s: float) -> float:
        """Bias-compensated RSS of the model with time constant ``lag_s`` (inf: singular)."""
        cross = self.ab + self.ab.T
        noise_cross = self.sab + self.sab.T
        gram = (self.aa + lag_s * cross + lag_s**2 * self.bb
                - (self.saa + lag_s * noise_cross + lag_s**2 * self.sbb))
        moment = self.ay + lag_s * self.by
        scale = np.sqrt(np.abs(np.diag(gram)))
        scale[scale == 0.0] = 1.0
        try:
            theta = np.linalg.solve(gram / np.outer(scale, scale), moment / scale)
        except np.linalg.LinAlgError:
            return math.inf
        return float(self.yy - theta @ (moment / scale))


def longest_lag_s(fs_hz: float) -> float:
    """The top of τ's search range at ``fs_hz`` (:data:`MAX_LAG_S` or 100 samples)."""
    return min(MAX_LAG_S, 100.0 / fs_hz)


def through_level_changes(position: FloatArray) -> FloatArray:
    """A quantised position drawn through the midpoint of each change of level.

    Between two changes the axis crossed one level's boundary, half a sample before the
    new level was read: a knot there, joined by straight lines. Where the axis creeps
    (fewer steps than samples) the low-passed position itself still steps, and
    re-quantising it gives almost no error; through these knots it moves as the axis did.

    Parameters
    ----------
    position : ndarray
        Quantised positions, one per sample.

    Returns
    -------
    ndarray
        The same length; the first and last samples kept.
    """
    change = np.flatnonzero(np.diff(position) != 0.0) + 1
    knots_t = np.concatenate(([0.0], change - 0.5, [len(position) - 1.0]))
    knots = np.concatenate(([position[0]], 0.5 * (position[change] + position[change - 1]),
                            [position[-1]]))
    return np.asarray(np.interp(np.arange(len(position), dtype=np.float64), knots_t, knots),
                      dtype=np.float64)


def quantisation_noise(signals: Signals) -> tuple[Signals, ...]:
    """Stand-ins for the position's quantisation error, as signals (empty: none found).

    The position, drawn through its changes of level (:func:`through_level_changes`; a
    resampled one as it is) and low-passed, is re-quantised with the recording's step
    (:attr:`Signals.position_step`, found before resampling) at each of
    :data:`QUANT_PHASES`; each error goes through the low-pass and the derivatives the
    regressors are built with. (Re-quantising the low-passed position itself gave the
    inertia column 1.24 × too little noise power and its lead 1.45 ×, 2–3 × where the axis
    creeps: there the low-passed position still steps, and its rounding barely changes.)

    Parameters
    ----------
    signals : Signals

    Returns
    -------
    tuple of Signals
        ``signals`` with ``position``, ``velocity`` and ``acceleration`` replaced by one
        re-quantisation error and its derivatives; empty when the position has no step.
    """
    step = signals.position_step
    if not step > 0:
        return ()
    # a resampled position lies between the levels already (the spline through them)
    position = np.asarray(signals.position)
    smooth = signals.lowpass(position if signals.resampled else through_level_changes(position))
    out = []
    for phase in QUANT_PHASES:
        shifted = smooth + phase * step
        error = np.round(shifted / step) * step - shifted
        velocity, acceleration = derivatives(signals.lowpass(error), step_s=1.0 / signals.fs_hz,
                                             segments=signals.segments)
        out.append(replace(signals, position=error, velocity=velocity, acceleration=acceleration))
    return tuple(out)


def _noise_term(term: Term) -> Term:
    """``term`` as it acts on the quantisation error: itself when linear in the motion."""
    if term.effect in NOISY_EFFECTS or (term.effect == "base" and term.key in NOISY_KEYS):
        return term
    width = len(term.labels)

    def build(signals: Signals) -> FloatArray:
        return np.zeros((len(signals), width))

    return replace(term, key=f"quiet:{width}", filtered=True, build=build, friction=False)


class LagProblem:
    """The Gram sums of one model's columns and leads on ``rows``, per alignment and group.

    Parameters
    ----------
    designer : Designer
        Builds (and caches) the model's columns on ``signals``.
    signals : Signals
    rows : ndarray of intp
        The rows fitted, in time order.
    model : Model
        Its terms (the lag and shift are searched here).
    groups : int
        Groups of rows for the jackknife (1: none): ``BLOCK_S`` blocks of the recording,
        block ``b`` in group ``b mod groups``.
    shift_grid : tuple of float
        The alignments tried, sample periods, evenly spaced.
    noise : (Designer, tuple of Signals), optional
        :func:`quantisation_noise` of ``signals`` and the designer of its columns, shared
        by the problems of one search (default: computed here).
    """

    def __init__(self, designer: Designer, signals: Signals, rows: IndexArray, model: Model,
                 groups: int = 1, shift_grid: tuple[float, ...] = SHIFT_GRID,
                 noise: tuple[Designer, tuple[Signals, ...]] | None = None) -> None:
        self.designer = designer
        self.shift_grid = shift_grid
        self.signals = signals
        self.rows = rows
        self.model = replace(model, lag_s=0.0, shift_s=0.0)
        block = (rows // max(1, round(BLOCK_S * signals.fs_hz))) % groups
        self.parts = [np.flatnonzero(block == g) for g in range(groups)]
        noise_designer, quantised = noise or (Designer(), quantisation_noise(signals))
        noise_model = replace(self.model, terms=tuple(_noise_term(t) for t in model.terms))
        self.noise: list[tuple[Designer, Model, Signals, float]] = [
            (noise_designer, noise_model, n, 1.0 / len(quantised)) for n in quantised]
        self._cache: dict[float, list[_Grams]] = {}
        self._full: dict[tuple[int, int], tuple[FloatArray, FloatArray]] = {}
        self._taps: dict[tuple[int, int], list[tuple[FloatArray, FloatArray]]] = {}
        fs = signals.fs_hz
        self.lag_grid = np.geomspace(0.5 / fs, longest_lag_s(fs), 20)

    def _pair(self, designer: Designer, model: Model, signals: Signals,
              shift: float) -> tuple[FloatArray, FloatArray]:
        """Columns and leads at ``t + shift`` on the rows (shifted there only)."""
        key = (id(model), id(signals))
        if key not in self._full:
            delay = model.friction_delay
            columns = [designer.columns(term, signals, delay) for term in model.terms]
            leads = [designer.lag_columns(term, signals, delay) if term.lagged
                     else np.zeros_like(block) for term, block in zip(model.terms, columns,
                                                                       strict=True)]
            self._full[key] = (np.hstack(columns), np.hstack(leads))
        full_columns, full_leads = self._full[key]
        return (fractional_shift(full_columns, shift, self.rows),
                fractional_shift(full_leads, shift, self.rows))

    def _tap_grams(self, designer: Designer, model: Model, signals: Signals,
                   ) -> list[tuple[FloatArray, FloatArray]]:
        """Per group: the Gram matrix of the four cubic-interpolation taps of ``[columns,
        leads]`` (rows ``r − 1 … r + 2``) and their products with the effort. Any alignment
        in ``[0, 1]`` sample is a weighting of these taps, so its sums follow from them
        without shifting the columns again."""
        key = (id(model), id(signals))
        if key not in self._taps:
            self._pair(designer, model, signals, 0.0)  # the unshifted blocks, cached
            full = np.hstack(self._full[key])
            y = self.signals.effort_filtered
            found = []
            for part in self.parts:
                rows = self.rows[part]
                taps = np.hstack([np.take(full, np.clip(rows + k, 0, len(full) - 1), axis=0)
                                  for k in (-1, 0, 1, 2)])
                found.append((taps.T @ taps, taps.T @ y[rows]))
            self._taps[key] = found
        return self._taps[key]

    def _grams_from_taps(self, shift: float) -> list[_Grams]:
        """:meth:`grams` for ``0 ≤ shift ≤ 1`` from :meth:`_tap_grams`."""
        u = shift
        weights = np.array([-u * (u - 1) * (u - 2) / 6, (u + 1) * (u - 1) * (u - 2) / 2,
                            -(u + 1) * u * (u - 2) / 2, (u + 1) * u * (u - 1) / 6])
        p = len(self.model.labels)
        mix = np.kron(weights[:, None], np.eye(2 * p))  # the taps → the shifted [a, b]

        def blocks(gram: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
            shifted = mix.T @ gram @ mix
            return shifted[:p, :p], shifted[:p, p:], shifted[p:, p:]

        y = self.signals.effort_filtered[self.rows]
        main = self._tap_grams(self.designer, self.model, self.signals)
        noise = [(self._tap_grams(d, m, n), w) for d, m, n, w in self.noise]
        groups = []
        for g, part in enumerate(self.parts):
            gram, moment = main[g]
            aa, ab, bb = blocks(gram)
            ay_by = mix.T @ moment
            saa, sab, sbb = np.zeros((p, p)), np.zeros((p, p)), np.zeros((p, p))
            for taps, weight in noise:
                naa, nab, nbb = blocks(taps[g][0])
                saa += weight * naa
                sab += weight * nab
                sbb += weight * nbb
            yp = y[part]
            groups.append(_Grams(aa, ab, bb, ay_by[:p], ay_by[p:], float(yp @ yp),
                                 saa, sab, sbb))
        return groups

    def grams(self, shift: float) -> list[_Grams]:
        """Per-group sums at the alignment ``shift`` (sample periods), cached."""
        if shift not in self._cache and 0.0 <= shift <= 1.0:
            self._cache[shift] = self._grams_from_taps(shift)
        if shift not in self._cache:
            a, b = self._pair(self.designer, self.model, self.signals, shift)
            y = self.signals.effort_filtered[self.rows]
            noise = [(*self._pair(d, m, n, shift), w) for d, m, n, w in self.noise]
            groups = []
            for part in self.parts:
                ap, bp, yp = a[part], b[part], y[part]
                p = ap.shape[1]
                saa, sab, sbb = np.zeros((p, p)), np.zeros((p, p)), np.zeros((p, p))
                for na, nb, weight in noise:
                    na, nb = na[part], nb[part]
                    saa += weight * na.T @ na
                    sab += weight * na.T @ nb
                    sbb += weight * nb.T @ nb
                groups.append(_Grams(ap.T @ ap, ap.T @ bp, bp.T @ bp, ap.T @ yp, bp.T @ yp,
                                     float(yp @ yp), saa, sab, sbb))
            self._cache[shift] = groups
        return self._cache[shift]

    def _sums(self, shift: float, without: int | None) -> _Grams:
        groups = self.grams(shift)
        total = groups[0]
        for g in groups[1:]:
            total = total + g
        return total if without is None else total - groups[without]

    def best_lag(self, shift: float, without: int | None = None) -> tuple[float, float]:
        """``(rss, τ)`` minimising the compensated RSS at ``shift`` (grid + bounded search)."""
        sums = self._sums(shift, without)
        grid = self.lag_grid
        costs = [sums.rss(float(t)) for t in grid]
        best = int(np.argmin(costs))
        low, high = grid[max(best - 1, 0)], grid[min(best + 1, len(grid) - 1)]
        result = minimize_scalar(lambda u: sums.rss(math.exp(u)),
                                 bounds=(math.log(low), math.log(high)), method="bounded",
                                 options={"xatol": 1e-4})
        lag = math.exp(float(result.x))
        rss = sums.rss(lag)
        if costs[best] < rss:
            return costs[best], float(grid[best])
        return rss, lag

    def estimate(self, without: int | None = None) -> tuple[float, float]:
        """``(τ, δ)`` (s, sample periods) minimising the compensated RSS, ``without`` a group.

        ``δ`` is searched on ``shift_grid``, its profile minimum refined by a parabola
        through the best point and its neighbours, and ``τ`` searched again there.
        """
        return self.estimate_rss(without)[1:]

    def estimate_rss(self, without: int | None = None) -> tuple[float, float, float]:
        """``(rss, τ, δ)``: :meth:`estimate` and the compensated RSS it reaches."""
        grid = self.shift_grid
        profile = [self.best_lag(float(s), without) for s in grid]
        costs = np.array([p[0] for p in profile])
        best = int(np.argmin(costs))
        shift = float(grid[best])
        if 0 < best < len(grid) - 1:
            left, mid, right = costs[best - 1], costs[best], costs[best + 1]
            curvature = left - 2 * mid + right
            if curvature > 0:
                step = grid[1] - grid[0]
                shift += float(0.5 * step * (left - right) / curvature)
        rss, lag = self.best_lag(shift, without)
        if rss > costs[best]:
            rss, shift, lag = float(costs[best]), float(grid[best]), profile[best][1]
        return rss, lag, shift


#: Friction delays tried with the lag, sample periods (:attr:`Model.friction_delay`).
FRICTION_DELAYS = (0.0, 0.25, 0.5, 0.75, 1.0)
def search_lag(designer: Designer, signals: Signals, rows: IndexArray, model: Model) -> Model:
    """``model`` with the current-loop lag, effort lead and friction delay that fit best.

    Searched on :func:`moving_rows` of ``rows``: ``(τ, δ)`` at each of
    :data:`FRICTION_DELAYS`, the least compensated RSS kept. The friction delay: a
    simulator that steps friction on the previous step's velocity (explicit Euler, this
    project's) switches it half a sample after the motion; the friction columns taken from
    the velocity that much earlier (a switching instant a sample off at each reversal is an
    error in the Coulomb column whose lead shortens τ). 0 for a drive whose friction
    switches with the motion.

    Parameters
    ----------
    designer : Designer
    signals : Signals
    rows : ndarray of intp
        The training rows.
    model : Model
        The current model (its own lag and shift are replaced).

    Returns
    -------
    Model
        With ``lag_s``, ``shift_s`` and ``friction_delay`` minimising the bias-compensated
        RSS.
    """
    rows = moving_rows(signals, rows)
    noise = (Designer(), quantisation_noise(signals))  # the same for every delay
    results = []
    for delay in FRICTION_DELAYS:
        delayed = replace(model, friction_delay=delay)
        problem = LagProblem(designer, signals, rows, delayed, noise=noise)
        results.append((*problem.estimate_rss(), delay))
    _, lag_s, shift, delay = min(results)
    return replace(model, lag_s=lag_s, shift_s=shift / signals.fs_hz, friction_delay=delay)


def jackknife_lag(designer: Designer, signals: Signals, rows: IndexArray, model: Model,
                  groups: int) -> tuple[Model, float]:
    """``(τ, δ)`` on ``rows`` and the delete-a-group jackknife uncertainty of ``τ``.

    Parameters
    ----------
    designer : Designer
    signals : Signals
    rows : ndarray of intp
        Every usable row, in time order (searched on their :func:`moving_rows`).
    model : Model
        The named model (its lag and shift are searched again on ``rows``; its friction
        delay is kept).
    groups : int
        Contiguous groups; each is left out once and ``(τ, δ)`` searched again.

    Returns
    -------
    model, std_s : Model, float
        ``model`` with the lag and shift found on every row, and
        ``√((G − 1)/G · Σ (τ₋g − τ̄)²)`` in s.
    """
    rows = moving_rows(signals, rows)
    problem = LagProblem(designer, signals, rows, model, groups=groups,
                         shift_grid=JACKKNIFE_SHIFT_GRID)
    lag_s, shift = problem.estimate()
    replicates = np.array([problem.estimate(without=g)[0] for g in range(groups)])
    spread = float(np.sum((replicates - replicates.mean()) ** 2))
    std = math.sqrt((groups - 1) / groups * spread)
    return replace(model, lag_s=lag_s, shift_s=shift / signals.fs_hz), std
