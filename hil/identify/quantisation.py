"""The quantisation step of a recorded signal, read off its values: one rule for the
encoder's position count and the drive's torque LSB.

A quantised signal takes values ``offset + k·q`` for integer ``k``; the step ``q`` is the
largest spacing of which the gaps between neighbouring *distinct* values are (nearly) all
whole multiples. The distinct values, not the sample-to-sample changes, are used: slow
motion visits every level (the gaps are ``q``), and fast motion, where one sample moves
several counts, still leaves gaps of a few whole counts whose common divisor is ``q``
(the smallest change alone would be several counts, a low percentile of the changes
would not divide them all). Continuous data fits no grid and gives 0.

Limits: gaps of rounding noise (a value written with too few digits) are tolerated up to
:data:`GRID_TOLERANCE` of a step, and off-grid values (glitches) as long as their gaps
stay below ``1 − GRID_FRACTION`` of all; when every neighbouring level is more than about
``1/GRID_TOLERANCE`` counts away from the next (a single fast pass), a step slightly
coarser than the true one may fit as well, and steps finer than :data:`MAX_DIVISOR`-th of
the smallest gap are not sought.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: A gap fits the grid when it is within this fraction of a step of a whole multiple.
GRID_TOLERANCE = 0.05
#: ... and the grid fits when at least this share of the gaps fits (a glitch does not
#: hide it, continuous data fits by chance only about ``2·GRID_TOLERANCE`` of the time).
GRID_FRACTION = 0.95
#: A grid fitting fewer gaps than the best candidate by more than this share is not taken.
FRACTION_SLACK = 0.02
#: ... nor one further off the grid than RMS_SLACK × the closest + RMS_FLOOR (in steps).
RMS_SLACK = 2.0
RMS_FLOOR = 0.005
#: Candidate steps are low gaps divided by 1 … MAX_DIVISOR (fast motion).
MAX_DIVISOR = 32
#: The low gaps tried as multiples of the step (weighted percentiles; 0: the smallest).
BASE_PERCENTILES = (0.0, 1.0, 5.0, 10.0, 25.0)
#: Gaps below this fraction of the largest magnitude are float noise, not levels.
FLOAT_NOISE = 1e-9
#: At most this many gaps are checked per candidate (an even stride through them).
MAX_GAPS_CHECKED = 4096


def level_gaps(values: FloatArray) -> FloatArray:
    """Gaps between neighbouring distinct values, without float noise.

    Parameters
    ----------
    values : array
        The recorded signal (any order, any unit).

    Returns
    -------
    array
        The positive differences of the sorted distinct values, larger than
        :data:`FLOAT_NOISE` times the largest magnitude; empty for fewer than two levels.
    """
    data = np.asarray(values, dtype=np.float64)
    levels = np.unique(data[np.isfinite(data)])
    if levels.size < 2:
        return np.zeros(0)
    scale = max(float(np.max(np.abs(levels))), 1e-300)
    gaps = np.diff(levels)
    return np.asarray(gaps[gaps > FLOAT_NOISE * scale], dtype=np.float64)


@dataclass(frozen=True, slots=True)
class GridFit:
    """How well the level gaps fit the grids of some candidate steps.

    Attributes
    ----------
    step : array
        The candidate steps (the values' unit).
    fraction : array
        Share of the gaps within :data:`GRID_TOLERANCE` of a step of a whole multiple.
    off_grid_rms : array
        RMS distance of those gaps from their multiple, in steps of the candidate (a finer
        grid of the same data is further off in its own steps, a slightly wrong one too).
    """

    step: FloatArray
    fraction: FloatArray
    off_grid_rms: FloatArray


def grid_fit(gaps: FloatArray, steps: FloatArray) -> GridFit:
    """Score the candidate ``steps`` against the level ``gaps``.

    Parameters
    ----------
    gaps : array
        Gaps between neighbouring levels (:func:`level_gaps`).
    steps : array
        Candidate steps, same unit, > 0.

    Returns
    -------
    GridFit
    """
    ratio = gaps[None, :] / steps[:, None]
    off_grid = np.abs(ratio - np.round(ratio))
    fits = off_grid <= GRID_TOLERANCE
    fraction = fits.mean(axis=1)
    squares = np.where(fits, off_grid**2, 0.0).sum(axis=1)
    rms = np.sqrt(squares / np.maximum(fits.sum(axis=1), 1))
    return GridFit(step=steps, fraction=fraction, off_grid_rms=rms)


def best_step(fit: GridFit) -> float:
    """The largest candidate that fits as well as any: 0 when none fits.

    Parameters
    ----------
    fit : GridFit
        The scored candidates.

    Returns
    -------
    float
        Among the candidates fitting at least :data:`GRID_FRACTION` of the gaps and within
        :data:`FRACTION_SLACK` of the best share (a coarser grid that skips the odd gap of
        one more count is not as good), and no further off the grid than
        :data:`RMS_SLACK` × the closest plus :data:`RMS_FLOOR` (a grid slightly coarser than
        the true one fits gaps of many counts only roughly), the largest step.
    """
    if fit.step.size == 0:
        return 0.0
    good = fit.fraction >= max(GRID_FRACTION, float(fit.fraction.max()) - FRACTION_SLACK)
    if not bool(np.any(good)):
        return 0.0
    closest = float(fit.off_grid_rms[good].min())
    good &= fit.off_grid_rms <= RMS_SLACK * closest + RMS_FLOOR
    return float(fit.step[good].max())


def refine_step(values: FloatArray, step: float) -> float:
    """The least-squares step of the grid ``offset + k·step`` through the distinct values.

    Parameters
    ----------
    values : array
        The recorded signal.
    step : float
        A step its level gaps fit (:func:`best_step`).

    Returns
    -------
    float
        The slope of the sorted distinct values against their whole multiples ``k`` (each
        gap rounded to a multiple of ``step``, summed): rounding noise averages out over
        the whole range instead of biasing the step to one gap.
    """
    data = np.asarray(values, dtype=np.float64)
    levels = np.unique(data[np.isfinite(data)])
    multiple = np.concatenate([[0.0], np.cumsum(np.round(np.diff(levels) / step))])
    if multiple[-1] < 1:
        return step
    return float(np.polyfit(multiple, levels, 1)[0])


def candidate_steps(gaps: FloatArray) -> FloatArray:
    """Candidate steps: low gaps divided by 1 … :data:`MAX_DIVISOR`.

    Parameters
    ----------
    gaps : array
        Gaps between neighbouring levels (:func:`level_gaps`), not empty.

    Returns
    -------
    array
        The distinct candidates, ascending.
    """
    bases = np.unique(np.percentile(gaps, BASE_PERCENTILES, method="lower"))
    divisors = np.arange(1, MAX_DIVISOR + 1, dtype=np.float64)
    return np.unique(np.outer(bases, 1.0 / divisors).ravel())


def quantisation_step(values: FloatArray) -> float:
    """The step of the grid the values lie on (their resolution); 0 when they fit none.

    Parameters
    ----------
    values : array
        A recorded signal: encoder position (slow or fast motion), reported torque, ….

    Returns
    -------
    float
        The largest step ``q`` such that the gaps between the distinct values are (nearly)
        all whole multiples of ``q``, in the values' unit; 0 for continuous data or fewer
        than two distinct values.

    Examples
    --------
    >>> float(round(quantisation_step(np.array([0.0, 0.0005, 0.0015, -0.001])), 12))
    0.0005
    >>> quantisation_step(np.array([0.0, 5.0, 11.0, 16.0, 22.0]))  # fast: 5, 6 counts
    1.0
    """
    gaps = level_gaps(values)
    if gaps.size == 0:
        return 0.0
    checked = gaps[:: max(1, gaps.size // MAX_GAPS_CHECKED)]
    step = best_step(grid_fit(checked, candidate_steps(gaps)))
    return refine_step(values, step) if step > 0 else 0.0
