"""Models linear in their coefficients: terms (regressor blocks), design matrix, LS fit.

A :class:`Model` is a tuple of :class:`Term` plus an optional current-loop lag. Each term
contributes named columns computed from :class:`~hil.diagnose.signals.Signals`; the lag
maps the model's effort ``T`` to what the drive reports, ``(1 + τ·s)·T`` (the reported
reference leads the actual torque through a first-order current loop). Nonlinear
parameters (a Stribeck velocity, a resonance, harmonic orders) are fixed inside a term
after a 1-D search and counted in the BIC penalty.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from hil.diagnose.signals import Signals, dilate, runs
from hil.errors import IdentificationError
from hil.identify.kinematics import zero_phase_lowpass

FloatArray = NDArray[np.float64]
IndexArray = NDArray[np.intp]

#: Velocity below which friction switching treats the axis as standing still (fraction of
#: the 99th percentile of |velocity|); avoids sign chatter on a quantised position.
STANDSTILL_FRACTION = 1e-3
LEAD_CUTOFF_RATIO = 0.8


@dataclass(frozen=True, slots=True, kw_only=True)
class Term:
    """A block of regressor columns belonging to one effect.

    ``build(signals)`` returns an ``(n, len(labels))`` array. ``nonlinear`` holds the
    parameters fixed by a search (they count in the BIC penalty); ``key`` identifies the
    columns for caching (equal keys mean equal columns).

    Attributes
    ----------
    effect : str
        The effect the columns belong to (``"base"`` or one of
        :data:`hil.diagnose.effects.EFFECTS`).
    labels : tuple of str
        The columns' coefficient names.
    build : callable
        ``Signals -> ndarray``: the columns over the whole recording, shape
        ``(len(signals), len(labels))`` (1-D for one column).
    key : str
        Identifies the columns in the :class:`Designer`'s caches.
    nonlinear : mapping of str to float
        The searched parameters fixed inside the columns.
    extra_params : int
        Search dimensions beyond ``nonlinear`` (e.g. chosen harmonic orders).
    filtered : bool
        The columns are already band-limited; otherwise the designer low-passes them.
    lagged : bool
        The columns pass through the current-loop lag.
    friction : bool
        Friction columns, built from the velocity: the model's
        ``friction_delay`` applies to the velocity they are built from.
    """

    effect: str
    labels: tuple[str, ...]
    build: Callable[[Signals], FloatArray] = field(compare=False, repr=False)
    key: str
    nonlinear: Mapping[str, float] = field(default_factory=dict)
    extra_params: int = 0  # search dimensions beyond ``nonlinear`` (e.g. chosen orders)
    filtered: bool = False  # columns already band-limited (built from filtered motion)
    lagged: bool = True  # passes through the current-loop lag (False: switching friction)
    friction: bool = False  # friction, built from the velocity: the friction delay applies


@dataclass(frozen=True, slots=True, kw_only=True)
class Model:
    """Terms, the current-loop time constant (0: no lag) and the effort's time lead.

    ``shift_s`` aligns effort and motion samples: the model is evaluated at ``t + shift_s``
    (a drive holds the torque it reports at ``t_k`` over the following period, so the
    motion it causes is centred up to a period later; how much depends on where the drive
    samples position). It is a property of the data, bounded to one sample period.

    Attributes
    ----------
    terms : tuple of Term
    lag_s : float
        Current-loop time constant τ, s; 0 for no lag.
    shift_s : float
        Time by which the effort leads the motion, s.
    friction_delay : float
        Sample periods by which the friction's switching trails the motion (searched with
        the current-loop lag, :mod:`hil.diagnose.lag`); 0: none.
    """

    terms: tuple[Term, ...]
    lag_s: float = 0.0
    shift_s: float = 0.0
    friction_delay: float = 0.0

    @property
    def labels(self) -> tuple[str, ...]:
        """Every coefficient's name, term by term (the design matrix's column order)."""
        return tuple(label for term in self.terms for label in term.labels)

    @property
    def effects(self) -> tuple[str, ...]:
        """Each term's effect, then ``"current_lag"`` when ``lag_s > 0``."""
        names = [term.effect for term in self.terms]
        if self.lag_s > 0:
            names.append("current_lag")
        return tuple(names)

    @property
    def n_params(self) -> int:
        """Coefficients plus searched parameters (the BIC's k).

        ``len(labels)``, plus every term's ``nonlinear`` and ``extra_params``, plus 1 when
        ``lag_s > 0``, plus 1 when ``friction_delay`` is not 0, plus 1.
        """
        searched = sum(len(t.nonlinear) + t.extra_params for t in self.terms)
        searched += 1 if self.friction_delay else 0
        return len(self.labels) + searched + (1 if self.lag_s > 0 else 0) + 1

    def has(self, effect: str) -> bool:
        """Whether ``effect`` is among :attr:`effects`."""
        return effect in self.effects

    def term(self, effect: str) -> Term | None:
        """The first term of ``effect``, or ``None`` when the model has none."""
        for term in self.terms:
            if term.effect == effect:
                return term
        return None


@dataclass(frozen=True, slots=True, kw_only=True)
class Fit:
    """Least-squares fit of a model on some rows of one recording.

    Attributes
    ----------
    model : Model
    coefficients : ndarray
        One per label of ``model``, in :attr:`Model.labels` order.
    covariance : ndarray
        ``σ²(ΦᵀΦ)⁻¹``; infinite everywhere when the design is (nearly) rank-deficient.
    rss : float
        Residual sum of squares on the fitted rows (effort units squared).
    n : int
        Rows fitted.
    sigma2 : float
        ``rss / (n − coefficients)``.
    n_effective : float
        Statistically independent rows (the BIC's sample count).
    """

    model: Model
    coefficients: FloatArray
    covariance: FloatArray
    rss: float
    n: int
    sigma2: float
    n_effective: float

    @property
    def bic(self) -> float:
        """BIC on the effective sample count (the filtered residual is band-limited)."""
        return bic(self.rss * self.n_effective / self.n, self.n_effective, self.model.n_params)

    def coef(self, label: str) -> float:
        """The coefficient of ``label``.

        Raises
        ------
        ValueError
            ``label`` is not in the model.
        """
        return float(self.coefficients[self.model.labels.index(label)])

    def std(self, label: str) -> float:
        """Standard deviation of the coefficient of ``label`` (infinite when rank-deficient).

        Raises
        ------
        ValueError
            ``label`` is not in the model.
        """
        index = self.model.labels.index(label)
        return float(math.sqrt(max(self.covariance[index, index], 0.0)))

    def block(self, labels: tuple[str, ...]) -> tuple[FloatArray, FloatArray]:
        """Coefficients and covariance of ``labels``.

        Parameters
        ----------
        labels : tuple of str
            Coefficient names of the model.

        Returns
        -------
        values, covariance : ndarray
            Shapes ``(len(labels),)`` and ``(len(labels), len(labels))``, in the order of
            ``labels``.

        Raises
        ------
        ValueError
            A label is not in the model.
        """
        index = [self.model.labels.index(label) for label in labels]
        return self.coefficients[index], self.covariance[np.ix_(index, index)]

    def as_dict(self) -> dict[str, float]:
        """Every coefficient by its label."""
        return {label: float(v) for label, v in zip(self.model.labels, self.coefficients,
                                                     strict=True)}


def bic(rss: float, n: float, k: int) -> float:
    """Bayesian information criterion of a Gaussian LS fit.

    Parameters
    ----------
    rss : float
        Residual sum of squares (floored at 1e-300).
    n : float
        Sample count.
    k : int
        Parameter count.

    Returns
    -------
    float
        ``n·ln(rss/n) + k·ln(n)``.
    """
    return n * math.log(max(rss, 1e-300) / n) + k * math.log(n)


def _assemble(model: Model, index: IndexArray,
              block: Callable[[Term, bool], FloatArray]) -> FloatArray:
    """The design on ``index``: each term's ``block(term, False)``, plus ``τ·block(term,
    True)`` (its lead) where the term passes through the current-loop lag."""
    blocks = []
    for term in model.terms:
        columns = block(term, False)[index]
        if model.lag_s > 0 and term.lagged:
            columns = columns + model.lag_s * block(term, True)[index]
        blocks.append(columns)
    return np.hstack(blocks) if blocks else np.zeros((len(index), 0))


class Designer:
    """Builds (and caches) design matrices of models on one or more recordings."""

    def __init__(self) -> None:
        self._cache: dict[tuple[int, str], FloatArray] = {}
        self._lag_cache: dict[tuple[int, str], FloatArray] = {}
        self._shift_cache: dict[tuple[int, str, bool, float], FloatArray] = {}
        self._delayed: dict[tuple[int, float], Signals] = {}
        self._band_cache: dict[tuple[int, str, bool, float, float], FloatArray] = {}

    def _source(self, term: Term, signals: Signals, delay: float) -> tuple[Signals, str]:
        """The signals ``term`` is built from and its cache key (a friction term with
        ``delay``: the velocity ``delay`` samples earlier)."""
        if not (term.friction and delay):
            return signals, term.key
        key = (id(signals), delay)
        if key not in self._delayed:
            earlier = fractional_shift(signals.velocity[:, None], -delay, np.arange(len(signals)))
            self._delayed[key] = replace(signals, velocity=earlier[:, 0])
        return self._delayed[key], f"{term.key}@{delay:g}"

    def columns(self, term: Term, signals: Signals, delay: float = 0.0) -> FloatArray:
        """A term's (low-passed) columns over the whole recording, cached.

        Parameters
        ----------
        term : Term
            Its columns are low-passed by :meth:`Signals.lowpass` unless ``filtered``.
        signals : Signals
        delay : float
            Friction delay, sample periods (applies to a ``friction`` term only).

        Returns
        -------
        ndarray
            Shape ``(len(signals), len(term.labels))``.

        Raises
        ------
        IdentificationError
            ``term.build`` returned another shape.
        """
        source, name = self._source(term, signals, delay)
        key = (id(signals), name)
        if key not in self._cache:
            block = np.asarray(term.build(source), dtype=np.float64)
            if block.ndim == 1:
                block = block[:, None]
            if block.shape != (len(signals), len(term.labels)):
                raise IdentificationError(
                    f"term {term.key} built {block.shape}, expected "
                    f"{(len(signals), len(term.labels))}"
                )
            if not term.filtered:
                block = np.column_stack(
                    [signals.lowpass(block[:, j]) for j in range(block.shape[1])]
                )
            self._cache[key] = block
        return self._cache[key]

    def lag_columns(self, term: Term, signals: Signals, delay: float = 0.0) -> FloatArray:
        """Time derivative of a term's columns, low-passed at ``LEAD_CUTOFF_RATIO·f_c``.

        The extra low-pass keeps the derivative of acceleration (jerk) from amplifying the
        position's quantisation noise: regressor noise would bias the lag towards zero.

        Parameters
        ----------
        term : Term
        signals : Signals
        delay : float
            Friction delay, sample periods (a ``friction`` term only).

        Returns
        -------
        ndarray
            Shape ``(len(signals), len(term.labels))``, per second.
        """
        key = (id(signals), self._source(term, signals, delay)[1])
        if key not in self._lag_cache:
            block = self.columns(term, signals, delay)
            cutoff = LEAD_CUTOFF_RATIO * signals.cutoff_hz
            self._lag_cache[key] = np.column_stack([
                signals.derivative(zero_phase_lowpass(block[:, j], fs_hz=signals.fs_hz,
                                                      cutoff_hz=cutoff, segments=signals.segments))
                for j in range(block.shape[1])
            ])
        return self._lag_cache[key]

    def lead(self, model: Model, signals: Signals, rows: IndexArray) -> FloatArray:
        """Time derivative of the lagged columns on ``rows`` (zeros where not lagged).

        Parameters
        ----------
        model : Model
            Its ``shift_s`` applies; its ``lag_s`` does not.
        signals : Signals
        rows : ndarray of intp

        Returns
        -------
        ndarray
            Shape ``(len(rows), len(model.labels))``.
        """
        delay = model.friction_delay
        shifted = replace(model, lag_s=0.0, friction_delay=0.0, terms=tuple(
            replace(term, key=f"lead:{self._source(term, signals, delay)[1]}",
                    build=_lead_builder(self, term, delay), filtered=True, friction=False)
            if term.lagged
            else replace(term, key=f"zero:{len(term.labels)}", build=_zero_builder(term),
                         filtered=True, friction=False)
            for term in model.terms
        ))
        return self.design(shifted, signals, rows)

    def _shifted(self, term: Term, signals: Signals, shift_s: float, lead: bool,
                 delay: float = 0.0) -> FloatArray:
        """A term's columns (or their lead) at ``t + shift_s``, over the whole recording."""
        key = (id(signals), self._source(term, signals, delay)[1], lead, shift_s)
        if key not in self._shift_cache:
            block = (self.lag_columns(term, signals, delay) if lead
                     else self.columns(term, signals, delay))
            if shift_s != 0.0:
                block = fractional_shift(block, shift_s * signals.fs_hz,
                                         np.arange(len(signals)))
            self._shift_cache[key] = block
        return self._shift_cache[key]

    def design(
        self, model: Model, signals: Signals, rows: IndexArray | None = None
    ) -> FloatArray:
        """The design matrix (lag and shift applied), on ``rows`` or on every sample.

        The shift is linear, so shifted columns and shifted leads are cached separately
        and combined as ``X(t + δ) + τ·Ẋ(t + δ)``.

        Parameters
        ----------
        model : Model
        signals : Signals
        rows : ndarray of intp, optional
            Default: every sample.

        Returns
        -------
        ndarray
            Shape ``(len(rows), len(model.labels))``.
        """
        index = np.arange(len(signals)) if rows is None else rows

        def block(term: Term, lead: bool) -> FloatArray:
            return self._shifted(term, signals, model.shift_s, lead, delay=model.friction_delay)

        return _assemble(model, index, block)

    def band_limited(self, model: Model, signals: Signals, rows: IndexArray,
                     cutoff_hz: float) -> tuple[FloatArray, FloatArray]:
        """Design and effort low-passed once more at ``cutoff_hz``, on ``rows``.

        The same zero-phase filter on the effort and on every column ("parallel
        filtering") keeps the model exact while it drops what lies above ``cutoff_hz``.

        Parameters
        ----------
        model : Model
        signals : Signals
        rows : ndarray of intp
        cutoff_hz : float
            Below :attr:`Signals.cutoff_hz` (at or above it the filter is skipped).

        Returns
        -------
        matrix, target : ndarray
            Shapes ``(len(rows), len(model.labels))`` and ``(len(rows),)``.
        """
        def band(values: FloatArray) -> FloatArray:
            if cutoff_hz >= signals.cutoff_hz:
                return values
            return np.column_stack([
                zero_phase_lowpass(values[:, j], fs_hz=signals.fs_hz, cutoff_hz=cutoff_hz,
                                   segments=signals.segments) for j in range(values.shape[1])])

        delay = model.friction_delay

        def block(term: Term, lead: bool) -> FloatArray:
            source_key = self._source(term, signals, delay)[1]
            key = (id(signals), source_key, lead, model.shift_s, cutoff_hz)
            if key not in self._band_cache:
                self._band_cache[key] = band(self._shifted(term, signals, model.shift_s, lead,
                                                           delay=delay))
            return self._band_cache[key]

        target_key = (id(signals), "effort", False, 0.0, cutoff_hz)
        if target_key not in self._band_cache:
            self._band_cache[target_key] = band(signals.effort_filtered[:, None])[:, 0]
        return _assemble(model, rows, block), self._band_cache[target_key][rows]

    def fit(self, model: Model, signals: Signals, rows: IndexArray) -> Fit:
        """Least squares on ``rows`` with covariance ``σ²(ΦᵀΦ)⁻¹``.

        The target is ``signals.effort_filtered``; the effective sample count is
        ``len(rows)·min(1, independence·decimation)``.

        Parameters
        ----------
        model : Model
        signals : Signals
        rows : ndarray of intp

        Returns
        -------
        Fit

        Raises
        ------
        IdentificationError
            No more rows than coefficients, or a term built columns of the wrong shape.
        """
        matrix = self.design(model, signals, rows)
        target = signals.effort_filtered[rows]
        independent = min(1.0, signals.independence * signals.decimation)
        return solve(model, matrix, target, n_effective=rows.size * independent)

    def predict(self, fit: Fit, signals: Signals) -> FloatArray:
        """The fitted model's effort on every sample of ``signals``.

        Parameters
        ----------
        fit : Fit
        signals : Signals
            The recording fitted, or another one of the same axis.

        Returns
        -------
        ndarray
            ``len(signals)`` values (N·m, or N on a linear axis).
        """
        return self.design(fit.model, signals) @ fit.coefficients


def fractional_shift(matrix: FloatArray, samples: float, rows: IndexArray) -> FloatArray:
    """``matrix`` at ``rows + samples`` (4-point cubic Lagrange interpolation).

    Stencils that leave the array repeat the edge value; those rows lie in the margins
    that :func:`hil.diagnose.signals.prepare` marks invalid.

    Parameters
    ----------
    matrix : ndarray
        Shape ``(n, m)``, one row per sample.
    samples : float
        The shift in sample periods (fractional, either sign).
    rows : ndarray of intp
        The rows wanted.

    Returns
    -------
    ndarray
        Shape ``(len(rows), m)``.
    """
    whole = math.floor(samples)
    u = samples - whole
    weights = (
        -u * (u - 1) * (u - 2) / 6,
        (u + 1) * (u - 1) * (u - 2) / 2,
        -(u + 1) * u * (u - 2) / 2,
        (u + 1) * u * (u - 1) / 6,
    )
    out = np.zeros((len(rows), matrix.shape[1]))
    tap = _taps(matrix, rows, whole)
    scaled = np.empty_like(out)
    for k, weight in enumerate(weights):
        if weight != 0.0:
            np.multiply(tap(k), weight, out=scaled)
            out += scaled
    return out


def _taps(matrix: FloatArray, rows: IndexArray, whole: int) -> Callable[[int], FloatArray]:
    """Stencil tap ``k`` (0 … 3): ``matrix[rows + whole + k − 1]``, edge repeated; views
    of one padded window when ``rows`` is a run of consecutive samples (the whole recording,
    most calls), else gathered."""
    n = len(rows)
    if n and int(rows[-1]) - int(rows[0]) == n - 1 and bool(np.all(np.diff(rows) == 1)):
        first, last = int(rows[0]) + whole - 1, int(rows[-1]) + whole + 2
        window = matrix[max(first, 0):max(min(last + 1, matrix.shape[0]), 0)]
        leading = min(max(-first, 0), n + 3)
        trailing = n + 3 - leading - len(window)
        if leading or trailing:
            window = np.concatenate([np.repeat(matrix[:1], leading, axis=0), window,
                                     np.repeat(matrix[-1:], trailing, axis=0)])
        return lambda k: window[k:k + n]
    return lambda k: np.take(matrix, np.clip(rows + (whole + k - 1), 0, matrix.shape[0] - 1),
                             axis=0)


def solve(model: Model, matrix: FloatArray, target: FloatArray, *, n_effective: float) -> Fit:
    """Column-scaled least squares; rank deficiency gives infinite variances.

    Parameters
    ----------
    model : Model
        The model whose design ``matrix`` is.
    matrix : ndarray
        Shape ``(n, p)``.
    target : ndarray
        Shape ``(n,)``.
    n_effective : float
        Stored in the fit for its BIC.

    Returns
    -------
    Fit
        Its covariance is infinite when the scaled matrix has rank below ``p`` or a
        singular value below 1e-10 of the largest.

    Raises
    ------
    IdentificationError
        ``n <= p``.
    """
    n, p = matrix.shape
    if n <= p:
        raise IdentificationError(f"{n} samples cannot determine {p} coefficients")
    scale = np.sqrt(np.sum(matrix**2, axis=0))
    scale[scale == 0.0] = 1.0
    scaled = matrix / scale
    coef_scaled, _, rank, singular = np.linalg.lstsq(scaled, target, rcond=None)
    coefficients = coef_scaled / scale
    residual = target - matrix @ coefficients
    rss = float(residual @ residual)
    sigma2 = rss / (n - p)
    if rank < p or singular[-1] < 1e-10 * singular[0]:
        covariance = np.full((p, p), np.inf)
    else:
        inverse = np.linalg.inv(scaled.T @ scaled)
        covariance = sigma2 * inverse / np.outer(scale, scale)
    return Fit(model=model, coefficients=coefficients, covariance=covariance, rss=rss, n=n,
               sigma2=sigma2, n_effective=n_effective)


def _lead_builder(designer: Designer, term: Term,
                  delay: float = 0.0) -> Callable[[Signals], FloatArray]:
    return lambda s: designer.lag_columns(term, s, delay)


def _zero_builder(term: Term) -> Callable[[Signals], FloatArray]:
    return lambda s: np.zeros((len(s), len(term.labels)))


def fit_percent(target: FloatArray, prediction: FloatArray) -> float:
    """``100·(1 − NRMSE)`` with NRMSE = ‖y − ŷ‖ / ‖y − mean(y)‖.

    Parameters
    ----------
    target, prediction : ndarray
        ``y`` and ``ŷ``.

    Returns
    -------
    float
        Fit in %, NaN when ``target`` is constant.
    """
    spread = float(np.linalg.norm(target - target.mean()))
    if spread == 0.0:
        return float("nan")
    return 100.0 * (1.0 - float(np.linalg.norm(target - prediction)) / spread)


def rms(values: FloatArray) -> float:
    """Root mean square of ``values``."""
    return float(np.sqrt(np.mean(values**2)))


def friction_direction(signals: Signals) -> FloatArray:
    """sgn(velocity) with a small standstill band (on the smoothed velocity).

    Parameters
    ----------
    signals : Signals
        Gives :attr:`Signals.velocity`.

    Returns
    -------
    ndarray
        −1, 0 or 1 per sample; 0 where ``|velocity|`` is at most
        :data:`STANDSTILL_FRACTION` of its 99th percentile.
    """
    velocity = signals.velocity
    band = STANDSTILL_FRACTION * float(np.percentile(np.abs(velocity), 99))
    out = np.sign(velocity)
    out[np.abs(velocity) <= band] = 0.0
    return out


#: A standstill (velocity in the standstill band) lasting at least this many samples is
#: sticking; shorter ones are a reversal passing through the band.
MIN_STICKING_SAMPLES = 3
#: :func:`moving_rows` keeps at least this part of the rows (else every row).
MIN_MOVING_SHARE = 0.5


def moving_rows(signals: Signals, rows: IndexArray) -> IndexArray:
    """``rows`` away from where the axis sticks (the lag's search; the halves test and the
    moving-rows gain of cogging and K_t ripple).

    While the axis sticks, friction holds whatever torque is applied, which no friction
    column expresses (the direction is 0 there): in a recording of this project's
    simulator with Stribeck friction the stuck rows held 96 % of the residual's sum of
    squares (the top of the chirp, where the lag's information lies, sticks for over half
    its samples). Left out: every standstill of at least :data:`MIN_STICKING_SAMPLES`
    samples and the low-pass's spread of it (the margin around a gap,
    ``max(3, ⌈2·fs/f_c⌉)`` samples). When fewer than :data:`MIN_MOVING_SHARE` of the rows
    are left, every row.

    Parameters
    ----------
    signals : Signals
    rows : ndarray of intp

    Returns
    -------
    ndarray of intp
    """
    still = friction_direction(signals) == 0
    sticking = np.zeros(len(still), dtype=bool)
    for start, stop in runs(still):
        if stop - start >= MIN_STICKING_SAMPLES:
            sticking[start:stop] = True
    margin = max(3, math.ceil(2.0 * signals.fs_hz / signals.cutoff_hz))
    near = dilate(sticking, margin)
    moving = rows[~near[rows]]
    return moving if moving.size >= MIN_MOVING_SHARE * rows.size else rows


def base_terms() -> tuple[Term, ...]:
    """``J·α + B·ω + T_c·sgn(ω)``.

    Returns
    -------
    tuple of Term
        ``inertia`` (acceleration), ``viscous`` (velocity) and ``coulomb``
        (:func:`friction_direction`, low-passed by the designer), all of effect ``"base"``.
    """
    return (
        Term(effect="base", labels=("inertia",), key="inertia",
             build=lambda s: s.acceleration, filtered=True),
        Term(effect="base", labels=("viscous",), key="viscous", build=lambda s: s.velocity,
             filtered=True, friction=True),
        Term(effect="base", labels=("coulomb",), key="coulomb", build=friction_direction,
             lagged=True, friction=True),
    )
