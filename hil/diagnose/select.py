"""Selection of effects: forward screening, then the best subset, judged on held-out data.

Decision rule (also written into the JSON report): a candidate effect is *significant*
when all of these hold (plus physical plausibility)

1. ``ΔBIC = BIC(extended) − BIC(current) ≤ −10`` on the training rows ("very strong"
   evidence on the Kass–Raftery scale; searched nonlinear parameters count in ``k``);
2. on the held-out rows the residual RMS drops by at least 1 %;
3. the 99 % confidence region of the effect's new parameters excludes zero (a Wald test
   of the key coefficients, ``cᵀC⁻¹c > χ²₀.₉₉(dim)``; for the current-loop lag the
   Gauss–Newton standard deviation of τ).

Forward rounds screen the effects: each round every remaining effect is proposed on top
of the current model (its nonlinear parameters searched there) and the significant one
with the most evidence per added parameter (the most negative ``ΔBIC / Δk``) is added for
the next round. Then :func:`best_subset` chooses the causes among every combination of
the effects significant in any round: a combination is kept when each of its effects is
significant against the others (so no effect is named that the others explain), and of
the kept ones, those within 1 % of the least held-out RMS count as equal and the one with
the fewest added parameters wins. The outcome does not depend on the order in which the
rounds met the effects; the causes come out ranked by the held-out RMS their removal adds,
each gain measured against the model with the causes ranked before it.

A fourth condition guards against effects outside the library: a known effect has one set
of parameters over the whole travel (:meth:`Evaluator.consistent`). Cogging and K_t ripple
must also gain 1 % on the held-out rows where the axis moves, fitted on the training rows
where it moves (:meth:`Evaluator.moving_gain`): while it sticks, friction holds any torque
of the angle. Every fit with K_t ripple is made in two stages (:func:`two_stage`).

A spring and gravity are told apart by their shape over the travel, not by a BIC margin: a
combination naming a spring without gravity is not kept when the torque it leaves is curved
(:meth:`Evaluator.curved`: a spring has no curvature, gravity's is minus its own value).
Once causes are chosen, every effect not named is proposed in each one's place
(:func:`_exchange`), so that which of two alike effects the forward path met first does not
decide; and a combination holding a function of the position (offset, gravity, spring) is
judged with its harmonic orders searched beside it when they were searched without it.
"""

from __future__ import annotations

import itertools
import logging
import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.special import chdtri

from hil.diagnose.effects import (
    EFFECTS,
    TWO_MASS_BAND,
    Context,
    local_scale,
    propose,
    search_shift,
)
from hil.diagnose.intervals import JACKKNIFE_COVERAGE_99, jackknife_solve
from hil.diagnose.lag import longest_lag_s
from hil.diagnose.model import (
    Designer,
    Fit,
    IndexArray,
    Model,
    Term,
    fit_percent,
    moving_rows,
    rms,
    solve,
)
from hil.diagnose.ripple import estimation_data, two_stage
from hil.diagnose.signals import Signals

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

DELTA_BIC_MAX = -10.0
MIN_HELDOUT_RMS_REDUCTION = 0.01
CONFIDENCE = 0.99
MAX_CAUSES = 5
#: A current-loop lag shorter than this many sample periods is not named: it cannot be
#: told apart from the sub-sample skew between effort and position sampling.
MIN_LAG_SAMPLES = 1.0
#: ... nor one within this part of the top of its search range (a τ that runs to the
#: range's end is not an estimate: the misfit wants more of the lead column than any lag
#: gives; another simulator's jittered 2^17-count recording ran τ to the 50 ms top,
#: docs/diagnose.md).
LAG_RANGE_MARGIN = 0.9
#: A structural resonance is named only when the load is at least this part of the inertia.
MIN_LOAD_FRACTION = 0.05
#: ...and its damping ratio at most this (a peak of Q ≥ 2.5): a better-damped shaft filter
#: is a smooth fall of the effective inertia over a decade of frequency, which sticking and
#: the encoder's quantisation make too (beside Stribeck friction, offered ζ up to 0.7, the
#: spurious resonances took 0.7; a gimbal's structural modes have ζ of 0.01-0.1).
MAX_RESONANCE_DAMPING = 0.2

#: An effect's coefficients fitted on the two halves of the travel differ significantly
#: at this level...
PERIODIC_ALPHA = 1e-3
#: ...and by at least this fraction of their size: not the same effect over the travel.
PERIODIC_MISMATCH = 0.5

#: Effects exempt from the halves test: the lag has no linear coefficient. K_t ripple is
#: halved on the rows where the angle sweeps only (:mod:`hil.diagnose.ripple`): on every
#: row its halves differ on true ripple (example_07: by 57 %), its column being largest
#: where the torque is, in the chirp, at one angle in one half (docs/diagnose.md).
NOT_HALVED = frozenset({"current_lag"})
#: Effects whose held-out gain must also hold away from sticking (:meth:`Evaluator.moving_gain`):
#: while the axis sticks friction holds any torque of the angle, and the sticking misfit,
#: which recurs at the same angles, is what their columns took up beside Stribeck friction.
MOVING_GAIN = frozenset({"cogging", "kt_ripple"})

KEY_LABELS = {
    "offset": ("offset",),
    "stribeck": ("stribeck_delta",),
    "gravity": ("gravity_cos", "gravity_sin"),
    "cable_spring": ("cable_stiffness",),
    "two_mass": ("load_inertia",),
}

DECISION_RULE = {
    "delta_bic_max": DELTA_BIC_MAX,
    "min_heldout_rms_reduction": MIN_HELDOUT_RMS_REDUCTION,
    "confidence": CONFIDENCE,
    "text": (
        "an effect is significant against a model when delta_bic = BIC(extended) - "
        "BIC(model) <= -10 on the training data, the held-out residual RMS drops by >= 1 %, "
        "the 99 % confidence region of its new parameters excludes zero, it is physically "
        "plausible and its coefficients agree on both halves of the travel (offset, gravity, "
        "spring and Stribeck friction also in its middle and at its ends); cogging and K_t "
        "ripple also gain >= 1 % fitted and judged on the rows where the axis moves (not "
        "sticking); the causes are "
        "the combination of screened effects in which each is significant against the "
        "others, with the least held-out RMS (within 1 %: the fewest parameters); a spring "
        "without gravity only when the torque it leaves has no curvature over the travel "
        "(jackknife, 99 %); ranked by "
        "the held-out RMS their removal adds, each gain against the causes ranked before it"
    ),
}


@dataclass(frozen=True, slots=True, kw_only=True)
class DataSet:
    """Rows of one recording's signals.

    Attributes
    ----------
    signals : Signals
    rows : ndarray of intp
        Indices into ``signals``.
    """

    signals: Signals
    rows: IndexArray


@dataclass(frozen=True, slots=True, kw_only=True)
class Gain:
    """What adding an effect to the current model gains, and the tests it is judged by.

    Attributes
    ----------
    rms_before_nm, rms_after_nm : float
        Held-out residual RMS of the current and the extended model (N·m, or N on a
        linear axis).
    fit_before_pct, fit_after_pct : float
        Held-out fit % of the current and the extended model.
    delta_bic : float
        ``BIC(extended) − BIC(current)`` on the training rows.
    wald_statistic, wald_threshold : float
        Wald statistic of the effect's key coefficients being zero (see
        :meth:`Evaluator.candidate`; for the current-loop lag ``(τ / std(τ))²``) and its
        χ² quantile at :data:`CONFIDENCE`.
    plausible : bool
        The fit is within the effect's physical constraints (see :func:`plausible`).
    """

    rms_before_nm: float
    rms_after_nm: float
    fit_before_pct: float
    fit_after_pct: float
    delta_bic: float
    wald_statistic: float
    wald_threshold: float
    plausible: bool = True

    @property
    def rms_reduction(self) -> float:
        """``1 − rms_after_nm / rms_before_nm`` (0 when ``rms_before_nm`` is 0)."""
        return 1.0 - self.rms_after_nm / self.rms_before_nm if self.rms_before_nm > 0 else 0.0

    @property
    def confident(self) -> bool:
        """The Wald statistic exceeds its threshold: the new parameters are not zero."""
        return self.wald_statistic > self.wald_threshold

    @property
    def significant(self) -> bool:
        """Plausible, and all three tests of the decision rule hold (module docstring)."""
        return (
            self.plausible
            and self.delta_bic <= DELTA_BIC_MAX
            and self.rms_reduction >= MIN_HELDOUT_RMS_REDUCTION
            and self.confident
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class Candidate:
    """An effect proposed on top of the current model, fitted and judged.

    Attributes
    ----------
    effect : str
    fit : Fit
        The extended model on the training rows.
    gain : Gain
        Against the model it extends.
    added_params : int
        Growth of :attr:`Model.n_params`, at least 1.
    lag_std_s : float
        Standard deviation of the current-loop time constant, s (NaN for other effects).
    """

    effect: str
    fit: Fit  # on the training rows
    gain: Gain
    added_params: int
    lag_std_s: float = math.nan


@dataclass(frozen=True, slots=True, kw_only=True)
class Selection:
    """The outcome of :func:`select`.

    Attributes
    ----------
    base : Fit
        The base model on the training rows, with the effort's lead applied.
    accepted : tuple of Candidate
        The causes, ranked, each gain measured against the model with the causes before
        it.
    rounds : tuple of tuple of Candidate
        Every candidate evaluated, per round (before pruning).
    """

    base: Fit
    accepted: tuple[Candidate, ...]
    rounds: tuple[tuple[Candidate, ...], ...]  # every candidate evaluated, per round

    @property
    def final(self) -> Fit:
        """The last cause's fit, or :attr:`base` when none was accepted."""
        return self.accepted[-1].fit if self.accepted else self.base


class Evaluator:
    """Fits on the training set, scores on the held-out set.

    Parameters
    ----------
    designer : Designer
    train, test : DataSet
        The rows to fit on and the held-out rows.
    counts_per_rev : int or None
        Encoder counts per revolution, when the position is quantised (bounds the
        harmonic orders searched).
    """

    def __init__(self, designer: Designer, train: DataSet, test: DataSet,
                 counts_per_rev: int | None) -> None:
        self.designer = designer
        self.train = train
        self.test = test
        self.counts_per_rev = counts_per_rev
        self.band_hz = TWO_MASS_BAND * train.signals.cutoff_hz
        self._fits: dict[tuple[object, ...], Fit] = {}
        self._candidates: dict[tuple[object, ...], Candidate] = {}
        # the rows away from sticking (the halves test and the moving gain of cogging and
        # K_t ripple); every row when fewer than half move
        self.train_moving = moving_rows(train.signals, train.rows)
        self.test_moving = moving_rows(test.signals, test.rows)

    def fit(self, model: Model, rows: IndexArray | None = None, part: str = "train") -> Fit:
        """``model`` fitted on the training rows (see :meth:`Designer.fit`; with K_t ripple in
        two stages, :func:`~hil.diagnose.ripple.two_stage`), cached.

        Parameters
        ----------
        model : Model
        rows : ndarray of intp, optional
            A part of the training rows (default: all of them), named by ``part``.
        part : str
            Names ``rows`` in the cache.

        Raises
        ------
        IdentificationError
            No more training rows than coefficients.
        """
        key = (part, *model_key(model))
        if key not in self._fits:
            rows = self.train.rows if rows is None else rows
            self._fits[key] = two_stage(self.designer,
                                        self.designer.fit(model, self.train.signals, rows),
                                        self.train.signals, rows)
        return self._fits[key]

    def heldout(self, fit: Fit, rows: IndexArray | None = None) -> tuple[float, float]:
        """Residual RMS and fit % on the held-out rows.

        Parameters
        ----------
        fit : Fit
        rows : ndarray of intp, optional
            A part of the held-out rows (default: all of them).

        Returns
        -------
        rms_nm, fit_pct : float
            RMS of filtered effort minus prediction (N·m, or N on a linear axis) and
            :func:`hil.diagnose.model.fit_percent` (%).
        """
        rows = self.test.rows if rows is None else rows
        target = self.test.signals.effort_filtered[rows]
        prediction = self.designer.predict(fit, self.test.signals)[rows]
        return rms(target - prediction), fit_percent(target, prediction)

    def lag_std(self, fit: Fit) -> float:
        """Gauss–Newton standard deviation of the current-loop time constant.

        Parameters
        ----------
        fit : Fit
            A model with a current-loop lag, on the training rows.

        Returns
        -------
        float
            In s; infinite when the Gauss–Newton normal matrix is singular.
        """
        signals, rows = self.train.signals, self.train.rows
        matrix = self.designer.design(fit.model, signals, rows)
        lead = self.designer.lead(fit.model, signals, rows)
        jacobian = np.column_stack((matrix, lead @ fit.coefficients))
        scale = np.sqrt(np.sum(jacobian**2, axis=0))
        scale[scale == 0] = 1.0
        try:
            inverse = np.linalg.inv((jacobian / scale).T @ (jacobian / scale))
        except np.linalg.LinAlgError:
            return math.inf
        return float(math.sqrt(max(fit.sigma2 * inverse[-1, -1], 0.0)) / scale[-1])

    def consistent(self, effect: str, fit: Fit) -> bool:
        """Whether ``effect``'s coefficients are the same on both halves of the travel.

        A known effect has one set of parameters over the whole travel: friction and
        inertia terms do not depend on the position, gravity and a spring are one function
        of it, cogging and K_t ripple repeat every revolution. Fitted on the rows below the
        median position and on those above it, their coefficients agree; for some effects
        also in the middle of the travel and at its ends (:func:`travel_splits`).
        Structure local to one stretch of travel (a tight spot in a bearing) or of another
        shape (a stiffening spring) is soaked up by some known effect's columns too, but
        fits them differently on the two sides of a cut. The coefficients are inconsistent
        when, on some cut, their difference is significant (χ² on the effect's
        coefficients, at :data:`PERIODIC_ALPHA` over the number of cuts) and at least
        :data:`PERIODIC_MISMATCH` of their mean size. Cogging and K_t ripple are compared
        on the rows away from sticking (:func:`~hil.diagnose.model.moving_rows`): while the
        axis sticks friction holds them with the rest, and the sticking misfit, which
        recurs at the same angles (a sine's turning points), splits their halves.

        Parameters
        ----------
        effect : str
        fit : Fit
            The model extended with ``effect``, on the training rows.

        Returns
        -------
        bool
            True when consistent, or when a half has too few rows to tell.
        """
        signals, rows = self.train.signals, self.train.rows
        labels = tuple(label for term in fit.model.terms if term.effect == effect
                       for label in term.labels)
        if effect in ("cogging", "kt_ripple"):
            labels = labels[:2]  # the strongest order (taken first) carries it
            rows = self.train_moving  # stuck, friction holds them: misfit only
        if not labels:
            return True
        if effect == "kt_ripple":  # the rows its coefficients come from (ripple.py)
            matrix, target, rows = estimation_data(self.designer, fit.model, signals, rows)
        else:
            matrix = self.designer.design(fit.model, signals, rows)
            target = signals.effort_filtered[rows]
        position = signals.position[rows]
        # weighted by each block's misfit: where the model misses most (a chirp, large
        # torque at one angle) the columns of any angle-dependent effect are constants that
        # soak up that misfit, in whichever half the chirp lies
        weight = 1.0 / local_scale(target - matrix @ fit.coefficients, rows,
                                   signals.fs_hz)
        splits = travel_splits(effect, position)
        for index, part in enumerate(splits):
            if not self._same_on_both_sides(fit, labels, matrix * weight[:, None],
                                            target * weight, part, len(splits)):
                log.debug("consistency of %s fails on split %d", effect, index)
                return False
        return True

    def curved(self, model: Model) -> bool:
        """Whether the torque ``model`` leaves holds a curvature over the travel.

        A spring's torque is linear in the angle, ``k·(θ − θ₀)``: it has no curvature
        anywhere; gravity's ``m·g·e·cos(θ + φ)`` has ``−`` its own value as its second
        derivative. The column ``cos(θ − θ_c)`` (``θ_c`` the middle of the travel; beside
        the model's constant its information is the curvature) is added to ``model`` on
        the training rows; the torque is curved when its coefficient differs from zero by
        more than its delete-a-group jackknife uncertainty times Student's t at 99 %
        (:mod:`hil.diagnose.intervals`: the jackknife sees the misfit that recurs at the
        same angles, which ``σ²(ΦᵀΦ)⁻¹`` does not).

        Parameters
        ----------
        model : Model

        Returns
        -------
        bool
            False also when ``model`` with the column is singular (no interval to judge by).
        """
        signals, rows = self.train.signals, self.train.rows
        position = signals.position[rows]
        centre = 0.5 * (float(np.min(position)) + float(np.max(position)))
        term = Term(effect="curvature", labels=("curvature",), key=f"curvature:{centre!r}",
                    build=lambda s: np.cos(s.position - centre))
        extended = replace(model, terms=(*model.terms, term))
        full = self.designer.fit(extended, signals, rows)
        fit = jackknife_solve(full, self.designer.design(extended, signals, rows),
                              signals.effort_filtered[rows])
        value, covariance = fit.block(("curvature",))
        std = math.sqrt(float(covariance[0, 0])) if math.isfinite(covariance[0, 0]) else 0.0
        statistic = abs(float(value[0])) / std if std > 0 else 0.0
        log.debug("curvature beside %s: t %.2f", model.effects, statistic)
        return statistic > JACKKNIFE_COVERAGE_99

    def moving_gain(self, model: Model, current: Model) -> float:
        """The held-out RMS reduction of ``model`` over ``current`` away from sticking.

        Both are fitted on the training rows where the axis moves and judged on the
        held-out rows where it moves (:func:`~hil.diagnose.model.moving_rows`).

        Parameters
        ----------
        model : Model
            ``current`` extended with an effect.
        current : Model

        Returns
        -------
        float
            ``1 − rms_after / rms_before``: the held-out gain itself when fewer than half
            the rows move (:func:`~hil.diagnose.model.moving_rows` keeps them all).
        """
        before, _ = self.heldout(self.fit(current, self.train_moving, "moving"), self.test_moving)
        after, _ = self.heldout(self.fit(model, self.train_moving, "moving"), self.test_moving)
        return 1.0 - after / before if before > 0 else 0.0

    @staticmethod
    def _same_on_both_sides(fit: Fit, labels: tuple[str, ...], matrix: FloatArray,
                            target: FloatArray, part: BoolArray, tests: int) -> bool:
        """Whether ``labels``' coefficients agree on the rows in ``part`` and the others
        (χ² at :data:`PERIODIC_ALPHA` / ``tests`` and :data:`PERIODIC_MISMATCH`)."""
        halves = []
        for side in (part, ~part):
            if np.count_nonzero(side) <= 4 * len(fit.model.labels):
                return True
            half = solve(fit.model, matrix[side], target[side],
                         n_effective=float(np.count_nonzero(side)))
            halves.append(half.block(labels))
        (a, ca), (b, cb) = halves
        difference = a - b
        try:
            statistic = float(difference @ np.linalg.solve(ca + cb, difference))
        except np.linalg.LinAlgError:
            return True
        if not math.isfinite(statistic):
            return True
        size = 0.5 * (float(np.linalg.norm(a)) + float(np.linalg.norm(b)))
        mismatch = float(np.linalg.norm(difference)) / size if size > 0 else 0.0
        significant = statistic > chi2_quantile(1.0 - PERIODIC_ALPHA / tests, len(labels))
        log.debug("consistency of %s: chi2 %.1f, mismatch %.2f", labels[0], statistic,
                  mismatch)
        return not (significant and mismatch >= PERIODIC_MISMATCH)

    def candidate(self, effect: str, model: Model, current: Fit) -> Candidate:
        """Fit ``model`` and judge what ``effect`` gains over ``current``.

        Parameters
        ----------
        effect : str
            The effect ``model`` adds.
        model : Model
            ``current``'s model extended with ``effect``.
        current : Fit
            The model it extends, on the training rows.

        Returns
        -------
        Candidate
            The Wald test is on :data:`KEY_LABELS` of ``effect`` (else on the labels
            ``model`` adds); for ``current_lag`` on τ with :meth:`lag_std`.
        """
        key = (effect, *model_key(model), *model_key(current.model))
        if key not in self._candidates:
            self._candidates[key] = self._candidate(effect, model, current)
        return self._candidates[key]

    def _candidate(self, effect: str, model: Model, current: Fit) -> Candidate:
        fit = self.fit(model)
        rms_before, fit_before = self.heldout(current)
        rms_after, fit_after = self.heldout(fit)
        lag_std = math.nan
        if effect == "current_lag":
            lag_std = self.lag_std(fit)
            statistic = (model.lag_s / lag_std) ** 2 if lag_std > 0 else 0.0
            threshold = chi2_quantile(CONFIDENCE, 1)
        else:
            labels = KEY_LABELS.get(effect) or tuple(
                label for label in model.labels if label not in current.model.labels
            )
            statistic, threshold = wald(fit, labels)
        plausible_fit = plausible(effect, fit, self.train.signals.fs_hz, self.band_hz)
        if plausible_fit and effect not in NOT_HALVED:
            plausible_fit = self.consistent(effect, fit)
        if plausible_fit and effect in MOVING_GAIN:
            moving = self.moving_gain(model, current.model)
            log.debug("%s away from sticking: held-out gain %.4f", effect, moving)
            plausible_fit = moving >= MIN_HELDOUT_RMS_REDUCTION
        gain = Gain(
            rms_before_nm=rms_before,
            rms_after_nm=rms_after,
            fit_before_pct=fit_before,
            fit_after_pct=fit_after,
            delta_bic=fit.bic - current.bic,
            wald_statistic=statistic,
            wald_threshold=threshold,
            plausible=plausible_fit,
        )
        return Candidate(effect=effect, fit=fit, gain=gain, lag_std_s=lag_std,
                         added_params=max(1, model.n_params - current.model.n_params))


#: Effects that are a function of the position over the whole travel: their middle is
#: the middle of the travel's range (see :func:`travel_splits`).
SHAPE_EFFECTS = frozenset({"offset", "gravity", "cable_spring"})
#: Effects whose information lies in the run's slow motions: their middle is the middle
#: half of the rows.
SLOW_EFFECTS = frozenset({"stribeck"})


def travel_splits(effect: str, position: FloatArray) -> list[BoolArray]:
    """The cuts of the travel the halves test compares a known effect's coefficients across.

    Parameters
    ----------
    effect : str
    position : ndarray
        Of the rows judged.

    Returns
    -------
    list of ndarray of bool
        The rows below the median position (the two halves); for :data:`SHAPE_EFFECTS`
        and :data:`SLOW_EFFECTS` also the middle against the two ends. For a function of
        the position the middle half of the travel's range (a stiffening spring's slope
        differs there from the ends', while its two halves agree); for Stribeck friction
        the rows between the 25th and 75th percentile of the positions, where a gimbal
        run's slow and small motions are (a friction raised there fits a Stribeck term
        that the reversals at the ends of the travel contradict). The other effects are
        only halved: their information lies in the speed and the acceleration, and the
        ends of a run hold one constant speed (the sweep), where a velocity-dependent
        friction's or a ripple's coefficients are not identifiable on their own.
    """
    halves = position < float(np.median(position))
    if effect in SHAPE_EFFECTS:
        low, high = float(np.min(position)), float(np.max(position))
        return [halves, np.abs(position - 0.5 * (low + high)) < 0.25 * (high - low)]
    if effect in SLOW_EFFECTS:
        low, high = (float(v) for v in np.percentile(position, [25, 75]))
        return [halves, (position >= low) & (position <= high)]
    return [halves]


def model_key(model: Model) -> tuple[object, ...]:
    """What identifies ``model``'s design: its terms' keys, lag and shift.

    Parameters
    ----------
    model : Model

    Returns
    -------
    tuple
        Equal for models with equal design matrices.
    """
    return (tuple(term.key for term in model.terms), model.lag_s, model.shift_s,
            model.friction_delay)


def plausible(effect: str, fit: Fit, fs_hz: float, band_hz: float) -> bool:
    """Physical sign constraints: a fit outside them describes something else.

    Parameters
    ----------
    effect : str
    fit : Fit
        The model extended with ``effect``.
    fs_hz : float
        Sample rate.
    band_hz : float
        Highest resonance that counts as resolved.

    Returns
    -------
    bool
        ``stribeck``: static friction above Coulomb. ``two_mass``: a load between
        :data:`MIN_LOAD_FRACTION` of the inertia and all of it, and a resonance at most
        ``band_hz``. ``cable_spring``: positive stiffness and non-negative hysteresis.
        ``current_lag``: τ at least :data:`MIN_LAG_SAMPLES` sample periods and short of
        the top of its search range (:data:`LAG_RANGE_MARGIN`). Else True.
    """
    values = fit.as_dict()
    if effect == "stribeck":
        return values["stribeck_delta"] > 0  # static friction above Coulomb
    if effect == "two_mass":  # a resolved resonance with a load that matters
        term = fit.model.term("two_mass")
        if term is None or not (
            MIN_LOAD_FRACTION * values["inertia"] < values["load_inertia"] < values["inertia"]
        ) or term.nonlinear["damping_ratio"] > MAX_RESONANCE_DAMPING:
            return False
        ratio = values["load_inertia"] / (values["inertia"] - values["load_inertia"])
        resonance = term.nonlinear["antiresonance_hz"] * math.sqrt(1 + ratio)
        return resonance <= band_hz
    if effect == "cable_spring":  # a spring, and a loop (when there is one) that dissipates
        return values["cable_stiffness"] > 0 and values.get("cable_hysteresis", 0.0) >= 0
    if effect == "current_lag":  # a shorter lag is indistinguishable from sampling skew
        return (fit.model.lag_s * fs_hz >= MIN_LAG_SAMPLES
                and fit.model.lag_s <= LAG_RANGE_MARGIN * longest_lag_s(fs_hz))
    return True


def chi2_quantile(probability: float, dof: int) -> float:
    """Quantile of the χ² distribution (``scipy.stats.chi2.ppf`` without its import cost).

    Parameters
    ----------
    probability : float
    dof : int
        Degrees of freedom.

    Returns
    -------
    float
    """
    return float(chdtri(dof, 1.0 - probability))


def wald(fit: Fit, labels: tuple[str, ...]) -> tuple[float, float]:
    """Wald statistic of ``labels`` being zero and its χ² threshold at :data:`CONFIDENCE`.

    Parameters
    ----------
    fit : Fit
    labels : tuple of str
        Coefficients tested jointly.

    Returns
    -------
    statistic, threshold : float
        ``cᵀC⁻¹c`` (0 when the covariance is not finite or singular) and the χ² quantile
        with ``len(labels)`` degrees of freedom.
    """
    values, covariance = fit.block(labels)
    threshold = chi2_quantile(CONFIDENCE, len(labels))
    if not np.all(np.isfinite(covariance)):
        return 0.0, threshold
    try:
        statistic = float(values @ np.linalg.solve(covariance, values))
    except np.linalg.LinAlgError:
        return 0.0, threshold
    return statistic, threshold


def select(evaluator: Evaluator, base_model: Model, *,
           effects: tuple[str, ...] = EFFECTS, hold_samples: float | None = None) -> Selection:
    """Greedy forward selection (see the module docstring for the rule).

    ``hold_samples`` is the time, in sample periods, by which the effort leads the motion
    it causes (0.5 for a drive that holds each torque sample over the following period);
    ``None`` estimates it in [0, 1] sample on the base model; a current-loop lag is
    searched jointly with its own alignment (a lag shifts the base model's best one).

    Parameters
    ----------
    evaluator : Evaluator
        The training and held-out data.
    base_model : Model
        The model every cause extends.
    effects : tuple of str
        The effects proposed (default :data:`hil.diagnose.effects.EFFECTS`).
    hold_samples : float or None
        The effort's lead, in sample periods, or ``None`` to search it.

    Returns
    -------
    Selection
        At most :data:`MAX_CAUSES` causes, pruned by :func:`prune`.

    Raises
    ------
    IdentificationError
        No more training rows than coefficients.
    """
    if hold_samples is None:
        ctx = Context(designer=evaluator.designer, signals=evaluator.train.signals,
                      rows=evaluator.train.rows, current=evaluator.fit(base_model))
        current = evaluator.fit(search_shift(ctx, base_model))
    else:
        shift_s = hold_samples / evaluator.train.signals.fs_hz
        current = evaluator.fit(replace(base_model, shift_s=shift_s))
    base = current
    rounds: list[tuple[Candidate, ...]] = []
    memory: dict[str, Model] = {}
    path = _forward(evaluator, current, effects, memory, rounds)
    chosen = best_subset(evaluator, base, tuple(rounds))
    for _ in range(RESTARTS):
        # the forward path proposed each effect on the models along it only: screen again
        # from the chosen causes, so that the harmonic orders (searched on the model they
        # extend) and the effects the path's model hid are proposed beside them too
        named = {c.effect for c in chosen}
        if not chosen or named == path:
            break
        start = chosen[-1].fit
        path = named | _forward(evaluator, start, tuple(e for e in effects if e not in named),
                                memory, rounds, len(named))
        chosen = best_subset(evaluator, base, tuple(rounds))
    if len(chosen) > 1:
        # each effect not named proposed in each cause's place too: the path proposed it
        # beside that cause only (a spring met beside an unmodelled lag, implausible there,
        # was never proposed beside the lag alone, and the gravity met first stayed)
        causes = tuple(c.effect for c in chosen)
        _exchange(evaluator, base, causes, effects, memory, rounds)
        again = best_subset(evaluator, base, tuple(rounds))
        names = {c.effect for c in again}
        if again and names != set(causes):
            _forward(evaluator, again[-1].fit, tuple(e for e in effects if e not in names),
                     memory, rounds, len(names))
            again = best_subset(evaluator, base, tuple(rounds))
        chosen = again
    return Selection(base=base, accepted=chosen, rounds=tuple(rounds))


def _exchange(evaluator: Evaluator, base: Fit, named: tuple[str, ...],
              effects: tuple[str, ...], memory: dict[str, Model],
              rounds: list[tuple[Candidate, ...]]) -> None:
    """One screening round on the model of the named causes without each one in turn
    (appended to ``rounds``): every effect not named proposed in that cause's place."""
    for cause in named:
        rest = tuple(e for e in named if e != cause)
        current = evaluator.fit(joint_model(base.model, tuple(rounds), rest))
        ctx = Context(designer=evaluator.designer, signals=evaluator.train.signals,
                      rows=evaluator.train.rows, current=current,
                      counts_per_rev=evaluator.counts_per_rev, memory=memory)
        evaluated: list[Candidate] = []
        for effect in effects:
            if effect in named:
                continue
            model = propose(effect, ctx)
            if model is not None:
                evaluated.append(evaluator.candidate(effect, model, current))
        rounds.append(tuple(evaluated))


#: Forward passes restarted from the best subset when it left the forward path.
RESTARTS = 2


def _forward(evaluator: Evaluator, current: Fit, effects: tuple[str, ...],
             memory: dict[str, Model], rounds: list[tuple[Candidate, ...]],
             named: int = 0) -> set[str]:
    """Forward screening rounds from ``current`` (appended to ``rounds``); the effects the
    path added."""
    accepted: set[str] = set()
    remaining = list(effects)
    while remaining and named + len(accepted) < MAX_CAUSES:
        ctx = Context(designer=evaluator.designer, signals=evaluator.train.signals,
                      rows=evaluator.train.rows, current=current,
                      counts_per_rev=evaluator.counts_per_rev, memory=memory)
        evaluated: list[Candidate] = []
        for effect in remaining:
            model = propose(effect, ctx)
            if model is None:
                continue
            candidate = evaluator.candidate(effect, model, current)
            log.debug("%s: %s", effect, candidate.gain)
            evaluated.append(candidate)
        rounds.append(tuple(evaluated))
        winners = [c for c in evaluated if c.gain.significant]
        if not winners:
            break
        # the most evidence, each added parameter charged as in best_subset's tie-break
        # (per added parameter, an offset went first for a gravity, and the orders of K_t
        # ripple beside it were never searched without the offset)
        best = min(winners, key=lambda c: c.gain.delta_bic - DELTA_BIC_MAX * c.added_params)
        accepted.add(best.effect)
        remaining.remove(best.effect)
        current = best.fit
    return accepted


Part = tuple[frozenset[str], tuple[Term, ...], float, float, float]


def _effect_model(candidate: Candidate) -> Part:
    """What ``candidate`` adds (its terms, the lag's time constant and the alignment and
    friction delay searched with it, NaN for other effects), and the effects of
    the model it was proposed on (its columns can depend on them: a Coulomb asymmetry is
    only added without a constant, the K_t-ripple weight is that model's prediction)."""
    model = candidate.fit.model
    terms = tuple(term for term in model.terms if term.effect == candidate.effect)
    context = frozenset(model.effects) - {"base", candidate.effect}
    if candidate.effect == "current_lag":
        return context, terms, model.lag_s, model.shift_s, model.friction_delay
    return context, terms, 0.0, math.nan, math.nan


def _variant(parts: list[Part], effects: tuple[str, ...]) -> Part:
    """The latest proposal whose model held only effects of ``effects``, else the latest."""
    inside = [part for part in parts if part[0] <= frozenset(effects)]
    return (inside or parts)[-1]


def _joint(base: Model, parts: dict[str, list[Part]], effects: tuple[str, ...]) -> Model:
    chosen = [_variant(parts[e], effects) for e in effects]
    terms = base.terms + tuple(term for part in chosen for term in part[1])
    lag = max((part[2] for part in chosen), default=0.0)
    # a lag comes with the effort/motion alignment and the friction delay searched with it
    shift = next((part[3] for part in chosen if not math.isnan(part[3])), base.shift_s)
    delay = next((part[4] for part in chosen if not math.isnan(part[4])), base.friction_delay)
    return replace(base, terms=terms, lag_s=lag, shift_s=shift, friction_delay=delay)


def screened_effects(rounds: tuple[tuple[Candidate, ...], ...]) -> tuple[str, ...]:
    """The effects significant in any forward round (the best subset's candidates).

    Parameters
    ----------
    rounds : tuple of tuple of Candidate
        :attr:`Selection.rounds`.

    Returns
    -------
    tuple of str
        In the order the rounds met them.
    """
    return tuple(dict.fromkeys(c.effect for candidates in rounds for c in candidates
                               if c.gain.significant))


def _parts(rounds: tuple[tuple[Candidate, ...], ...],
           effects: tuple[str, ...]) -> dict[str, list[Part]]:
    parts: dict[str, list[Part]] = {effect: [] for effect in effects}
    for candidates in rounds:  # every proposal of each screened effect, in round order
        for candidate in candidates:
            if candidate.effect in parts:
                parts[candidate.effect].append(_effect_model(candidate))
    return parts


def joint_model(base: Model, rounds: tuple[tuple[Candidate, ...], ...],
                effects: tuple[str, ...]) -> Model:
    """``effects`` fitted jointly on ``base``, with the columns :func:`best_subset` uses.

    Parameters
    ----------
    base : Model
        The base model (with the effort's lead).
    rounds : tuple of tuple of Candidate
        :attr:`Selection.rounds`.
    effects : tuple of str
        Effects proposed in ``rounds``.

    Returns
    -------
    Model
        Each effect's columns from its latest proposal on a model holding only effects of
        ``effects``.
    """
    return _joint(base, _parts(rounds, effects), effects)


def researched_model(designer: Designer, signals: Signals, rows: IndexArray,
                     counts_per_rev: int | None, base: Model,
                     rounds: tuple[tuple[Candidate, ...], ...],
                     effects: tuple[str, ...]) -> Model:
    """:func:`joint_model`, with the harmonic orders searched again beside the others
    where :func:`best_subset` judges them so (:func:`_searched_without_the_position`).

    Parameters
    ----------
    designer : Designer
    signals : Signals
    rows : ndarray of intp
        The training rows.
    counts_per_rev : int or None
        Encoder counts per revolution (bounds the orders searched).
    base : Model
    rounds : tuple of tuple of Candidate
        :attr:`Selection.rounds`.
    effects : tuple of str
        Effects proposed in ``rounds``.

    Returns
    -------
    Model
    """
    parts = _parts(rounds, effects)
    for effect in effects:
        if not _position_missed(parts, effect, effects):
            continue
        others = tuple(e for e in effects if e != effect)
        _propose_beside(Context(designer=designer, signals=signals, rows=rows,
                                current=designer.fit(_joint(base, parts, others), signals, rows),
                                counts_per_rev=counts_per_rev),
                        parts, effect, frozenset(others))
    return _joint(base, parts, effects)


def _propose_beside(ctx: Context, parts: dict[str, list[Part]], effect: str,
                    others: frozenset[str]) -> bool:
    """Propose ``effect`` on ``ctx``'s model of ``others`` and add its columns to ``parts``
    as found beside them; False when nothing was proposed."""
    model = propose(effect, ctx)
    if model is None:
        return False
    terms = tuple(term for term in model.terms if term.effect == effect)
    parts[effect].append((others, terms, 0.0, math.nan, math.nan))
    return True


def _holds(gain: Gain) -> bool:
    """The decision rule (:attr:`Gain.significant`)."""
    return gain.significant


def best_subset(evaluator: Evaluator, base: Fit,
                rounds: tuple[tuple[Candidate, ...], ...]) -> tuple[Candidate, ...]:
    """The set of causes, chosen among every combination of the screened effects.

    The forward rounds screen the effects: an effect significant in any round (accepted
    or not) is a candidate; in a combination its columns are those of its latest proposal
    made on a model holding only effects of that combination. Every combination of up to
    :data:`MAX_CAUSES` candidates is fitted jointly on the training rows and kept when
    each of its effects passes the decision rule against the same combination without
    it (held-out RMS reduction, ΔBIC, Wald, plausibility): no effect is kept that the
    others explain. Of the combinations kept, those within
    :data:`MIN_HELDOUT_RMS_REDUCTION` of the least held-out RMS are indistinguishable on
    the held-out data; of them the one with the fewest added parameters wins (then the
    least RMS). So the outcome does not depend on the order the forward rounds met the
    effects in.

    Parameters
    ----------
    evaluator : Evaluator
    base : Fit
        The base fit every cause extends.
    rounds : tuple of tuple of Candidate
        Every candidate of every forward round.

    Returns
    -------
    tuple of Candidate
        The causes, ranked by the held-out RMS their removal would add (largest first),
        each gain measured against the model with the causes ranked before it.
    """
    screened = screened_effects(rounds)
    parts = _parts(rounds, screened)
    if not screened:
        return ()
    kept = [(verdict[0], effects, verdict[1])
            for size in range(1, min(MAX_CAUSES, len(screened)) + 1)
            for effects in itertools.combinations(screened, size)
            if (verdict := (_judge_reproposed(evaluator, base, parts, effects)
                            if _searched_without_the_position(parts, effects) else None)
                or _judge_set(evaluator, base, parts, effects)
                or _judge_reproposed(evaluator, base, parts, effects)) is not None]
    if not kept:
        return ()
    # among the combinations the held-out data cannot tell apart (within 1 % of the least
    # held-out RMS) the training evidence decides, each added parameter charged the rule's
    # "very strong" -ΔBIC on top of BIC's own: the fewest parameters unless more buy that
    # (fewest parameters alone named an offset for a gravity whose curvature the BIC shows
    # by 50-150; the least BIC alone an asymmetric friction for an offset, by 8.6)
    least = min(entry[0] for entry in kept)
    close = [entry for entry in kept if entry[0] <= least * (1.0 + MIN_HELDOUT_RMS_REDUCTION)]
    evidence = {}
    for entry in close:
        model = _joint(base.model, parts, entry[1])
        added = model.n_params - base.model.n_params
        evidence[entry[1]] = evaluator.fit(model).bic - DELTA_BIC_MAX * added
    best = min(close, key=lambda entry: (evidence[entry[1]], entry[0]))
    _, effects, losses = best
    ranked = sorted(effects, key=lambda e: -losses[e])
    accepted: list[Candidate] = []
    current = base
    for index, effect in enumerate(ranked):
        model = _joint(base.model, parts, tuple(ranked[: index + 1]))
        candidate = evaluator.candidate(effect, model, current)
        accepted.append(candidate)
        current = candidate.fit
    return tuple(accepted)


#: Effects whose searched parameters depend on the model they extend (the harmonic orders:
#: searched beside an unmodelled gravity, cogging orders fit the gravity).
RESEARCHED = ("cogging", "kt_ripple")
#: Combinations up to this size are judged again with such effects searched on the others.
RESEARCH_SIZE = 3


#: Functions of the position alone: harmonic orders searched on a model without one fit it.
POSITION_SHAPES = frozenset({"offset", "gravity", "cable_spring"})


def _searched_without_the_position(parts: dict[str, list[Part]],
                                   effects: tuple[str, ...]) -> bool:
    """Whether a harmonic effect of ``effects`` comes with orders searched on a model
    without a function of the position that the others hold: they fit what that model
    missed of it, and the combination is judged with them searched again beside it (a
    spring beside cogging orders searched beside gravity lost to the gravity)."""
    return any(_position_missed(parts, effect, effects) for effect in effects)


def _position_missed(parts: dict[str, list[Part]], effect: str,
                     effects: tuple[str, ...]) -> bool:
    """Whether harmonic ``effect``'s orders were searched on a model without a function of
    the position that the rest of ``effects`` holds."""
    others = frozenset(effects) - {effect}
    return effect in RESEARCHED and bool(
        (others & POSITION_SHAPES) - _variant(parts[effect], effects)[0])


def _judge_reproposed(evaluator: Evaluator, base: Fit, parts: dict[str, list[Part]],
                      effects: tuple[str, ...]) -> tuple[float, dict[str, float]] | None:
    """A rejected combination judged again with its harmonic effects searched on the model
    of the others, when no screening round proposed them there (``parts`` gains them)."""
    if len(effects) > RESEARCH_SIZE:
        return None
    changed = False
    for effect in effects:
        others = frozenset(effects) - {effect}
        if effect not in RESEARCHED or not others:
            continue
        if any(part[0] == others for part in parts[effect]):
            continue
        current = evaluator.fit(_joint(base.model, parts, tuple(sorted(others))))
        ctx = Context(designer=evaluator.designer, signals=evaluator.train.signals,
                      rows=evaluator.train.rows, current=current,
                      counts_per_rev=evaluator.counts_per_rev)
        changed = _propose_beside(ctx, parts, effect, others) or changed
    return _judge_set(evaluator, base, parts, effects) if changed else None


def _judge_set(evaluator: Evaluator, base: Fit, parts: dict[str, list[Part]],
               effects: tuple[str, ...]) -> tuple[float, dict[str, float]] | None:
    """Held-out RMS of ``effects`` jointly and each one's drop-one loss, or ``None`` when
    one of them fails the decision rule against the others."""
    model = _joint(base.model, parts, effects)
    if ("cable_spring" in effects and "gravity" not in effects
            and evaluator.train.signals.axis_kind == "rotary" and evaluator.curved(model)):
        # a spring makes no curvature; on a rotary axis gravity does (a linear axis has no
        # gravity term: on an incline it is a constant)
        log.debug("set %s: a spring, and the torque left is curved over the travel", effects)
        return None
    losses: dict[str, float] = {}
    rms_after = math.nan
    for effect in effects:
        others = tuple(e for e in effects if e != effect)
        reduced = evaluator.fit(_joint(base.model, parts, others)) if others else base
        candidate = evaluator.candidate(effect, model, reduced)
        if not _holds(candidate.gain):
            log.debug("set %s: %s fails against the others: %s", effects, effect,
                      candidate.gain)
            return None
        losses[effect] = candidate.gain.rms_before_nm - candidate.gain.rms_after_nm
        rms_after = candidate.gain.rms_after_nm
    return rms_after, losses
