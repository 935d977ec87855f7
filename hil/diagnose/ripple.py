"""K_t ripple's coefficients from the rows where the angle sweeps (a two-stage fit).

The ripple's column ``T̂·sin kθ`` is largest where the torque is. Where the angle stands
nearly still (a chirp, a staircase step) ``sin kθ`` is a constant and the column a copy of
``T̂``: those rows say nothing about how the torque depends on θ, but with their large
torque they dominate the ripple's normal equations, and whatever the model misses there
along ``T̂`` (mostly ``J·α`` at high frequency) is taken as ripple at that one angle. On
example_07 (a chirp at a nearly fixed angle) this pulled the depth 23 % low. So the
ripple's parameters, their intervals and its halves test use only the rows over which the
angle sweeps at least a quarter period of the ripple's lowest order within a block; the
rest of the extended model is fitted on every training row with the ripple subtracted
(:func:`two_stage`), and the selection judges the jointly fitted model as before.

On those rows the effort and every column are low-passed once more, well below the
analysis cutoff (:func:`band_hz`, :func:`estimation_data`): the encoder's quantisation,
differentiated twice, is as large as the ripple in the inertia's column there, and as
errors in the regressors it biased the depth low and split the halves of the travel.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from hil.diagnose.model import Designer, Fit, IndexArray, Model, solve
from hil.diagnose.signals import Signals

FloatArray = NDArray[np.float64]

#: Blocks over which the angle's sweep is judged, s (those of the order search's weights).
SWEEP_BLOCK_S = 0.25
#: A block informs θ-dependence when kθ sweeps at least this much of a period.
SWEEP_FRACTION = 0.25
#: Fewer sweeping rows than this fraction of the training rows: keep every row.
MIN_SWEEP_SHARE = 0.2
#: The ripple's rows are low-passed again, at no less than this fraction of the cutoff...
BAND_FRACTION = 0.2
#: ...and at no less than this multiple of the ripple's highest frequency on them.
BAND_MARGIN = 2.0


def sweep_rows(signals: Signals, rows: IndexArray, lowest_order: int) -> IndexArray:
    """The rows whose block's angle covers a quarter period of ``lowest_order``.

    Parameters
    ----------
    signals : Signals
    rows : ndarray of intp
        Candidate rows (the training rows).
    lowest_order : int
        The ripple's lowest order, periods per revolution.

    Returns
    -------
    ndarray of intp
        The subset of ``rows``; all of ``rows`` when fewer than :data:`MIN_SWEEP_SHARE` of
        them sweep (the ripple is then estimated as before, from every row).
    """
    block = rows // max(1, round(SWEEP_BLOCK_S * signals.fs_hz))
    _, index = np.unique(block, return_inverse=True)
    position = signals.position[rows]
    high = np.full(index.max() + 1, -np.inf)
    low = np.full(index.max() + 1, np.inf)
    np.maximum.at(high, index, position)
    np.minimum.at(low, index, position)
    sweeps = (high - low)[index] * lowest_order >= SWEEP_FRACTION * 2.0 * math.pi
    if sweeps.sum() < MIN_SWEEP_SHARE * rows.size:
        return rows
    return rows[sweeps]


def orders_of(model: Model) -> tuple[int, ...]:
    """The orders of ``model``'s ``kt_ripple`` term (empty without one).

    Parameters
    ----------
    model : Model

    Returns
    -------
    tuple of int
        Periods per revolution, in the term's column order.
    """
    term = model.term("kt_ripple")
    if term is None:
        return ()
    return tuple(int(label.removeprefix("kt_sin")) for label in term.labels[::2])


def band_hz(signals: Signals, rows: IndexArray, orders: tuple[int, ...]) -> float:
    """Cutoff of the second low-pass of the ripple's rows.

    The encoder's quantisation, differentiated twice, puts noise into the inertia's column
    (and the ripple's weight) that rises with frequency up to the analysis cutoff; at
    constant speed it is as large as the ripple itself (5 mN·m at 2²⁰ counts/rev), and as
    errors in the regressors it biased the depth low and made the halves of the travel
    disagree. The ripple's own information lies at ``k·|ω|/2π``, far below: low-passing
    effort and columns alike keeps the model exact and drops the noise above.

    Parameters
    ----------
    signals : Signals
    rows : ndarray of intp
        The sweeping rows.
    orders : tuple of int
        The ripple's orders.

    Returns
    -------
    float
        ``max(BAND_FRACTION·f_c, BAND_MARGIN·k_max·|ω|₉₉/2π)``, at most the cutoff ``f_c``.
    """
    speed = float(np.percentile(np.abs(signals.velocity[rows]), 99)) if rows.size else 0.0
    highest = max(orders, default=0) * speed / (2.0 * math.pi)
    return min(signals.cutoff_hz, max(BAND_FRACTION * signals.cutoff_hz, BAND_MARGIN * highest))


def estimation_rows(signals: Signals, rows: IndexArray,
                    orders: tuple[int, ...]) -> tuple[IndexArray, float]:
    """The sweeping rows of ``orders``, thinned for their band (:func:`band_hz`).

    Parameters
    ----------
    signals : Signals
    rows : ndarray of intp
        The rows available.
    orders : tuple of int
        The ripple's orders (not empty).

    Returns
    -------
    rows : ndarray of intp
        :func:`sweep_rows` of the lowest order, thinned to about 2.5 rows per cycle of the
        band (the rows of a band-limited residual are otherwise correlated, and its
        least-squares covariance too small); every row when too few sweep (band-limited
        and thinned, every row let a spurious order-9 ripple pass beside a Stribeck
        friction and a lag, which the whole band rejects).
    band_hz : float
        :func:`band_hz` on the sweeping rows (the cutoff when every row is kept).
    """
    sweeping = sweep_rows(signals, rows, min(orders))
    if sweeping.size == rows.size:  # too few sweep: every row, the whole band, as before
        return rows, signals.cutoff_hz
    cutoff = band_hz(signals, sweeping, orders)
    return sweeping[:: max(1, int(signals.cutoff_hz / cutoff))], cutoff


def estimation_data(designer: Designer, model: Model, signals: Signals,
                    rows: IndexArray) -> tuple[FloatArray, FloatArray, IndexArray]:
    """Where the ripple's coefficients are estimated: the sweeping rows, band-limited.

    Parameters
    ----------
    designer : Designer
    model : Model
        A model with a ``kt_ripple`` term (otherwise ``rows``, not filtered again).
    signals : Signals
    rows : ndarray of intp
        The rows available (training, or every usable row).

    Returns
    -------
    matrix, target : ndarray
        ``model``'s design and the effort, both low-passed at :func:`band_hz`, on the
        rows returned.
    rows : ndarray of intp
        :func:`estimation_rows`.
    """
    orders = orders_of(model)
    if not orders:
        return designer.design(model, signals, rows), signals.effort_filtered[rows], rows
    kept, cutoff = estimation_rows(signals, rows, orders)
    matrix, target = designer.band_limited(model, signals, kept, cutoff)
    return matrix, target, kept


def fit_on_sweep(designer: Designer, model: Model, signals: Signals, rows: IndexArray) -> Fit:
    """``model`` fitted on :func:`estimation_data` of ``rows``.

    Parameters
    ----------
    designer : Designer
    model : Model
    signals : Signals
    rows : ndarray of intp

    Returns
    -------
    Fit
        Least squares (``σ²(ΦᵀΦ)⁻¹``, the rows taken as independent).
    """
    matrix, target, kept = estimation_data(designer, model, signals, rows)
    return solve(model, matrix, target, n_effective=float(kept.size))


def two_stage(designer: Designer, fit: Fit, signals: Signals, rows: IndexArray) -> Fit:
    """``fit``'s model in two stages: the ripple from the sweeping rows, the rest from all.

    Parameters
    ----------
    designer : Designer
    fit : Fit
        Fitted on ``rows``; returned unchanged without a ``kt_ripple`` term.
    signals : Signals
    rows : ndarray of intp
        The training rows.

    Returns
    -------
    Fit
        Stage one: ``fit``'s model on :func:`estimation_data` gives the ripple's
        coefficients and their covariance; stage two: every other coefficient by least squares on
        ``rows`` with the ripple's contribution subtracted (its covariance from that fit;
        the two blocks uncorrelated). ``rss`` on ``rows``.
    """
    term = fit.model.term("kt_ripple")
    if term is None:
        return fit
    stage_one = fit_on_sweep(designer, fit.model, signals, rows)
    labels = fit.model.labels
    ripple = np.isin(labels, term.labels)
    matrix = designer.design(fit.model, signals, rows)
    target = signals.effort_filtered[rows] - matrix[:, ripple] @ stage_one.coefficients[ripple]
    rest = replace(fit.model, terms=tuple(t for t in fit.model.terms if t is not term))
    stage_two = solve(rest, matrix[:, ~ripple], target, n_effective=fit.n_effective)
    coefficients = np.empty(len(labels))
    coefficients[ripple] = stage_one.coefficients[ripple]
    coefficients[~ripple] = stage_two.coefficients
    covariance = np.zeros((len(labels), len(labels)))
    covariance[np.ix_(ripple, ripple)] = stage_one.covariance[np.ix_(ripple, ripple)]
    covariance[np.ix_(~ripple, ~ripple)] = stage_two.covariance
    residual = signals.effort_filtered[rows] - matrix @ coefficients
    rss = float(residual @ residual)
    return replace(fit, coefficients=coefficients, covariance=covariance, rss=rss,
                   sigma2=rss / max(rows.size - len(labels), 1))
