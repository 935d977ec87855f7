"""Process capability: Cp, Cpk (within-σ from the average moving range), Pp, Ppk (overall σ),
each with a two-sided confidence interval and the n it rests on (docs/fleet.md §1)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats

from hil.errors import InputError

D2 = 1.128
"""E|x₁ − x₂| / σ for two normal observations (moving ranges of span 2; Montgomery App. VI)."""
D4 = 3.267
"""Upper moving-range limit factor for span 2: UCL_MR = D4 · MR̄."""

# Variance of one moving range and covariance of two adjacent ones, in units of σ², for
# independent normal data (exact: |d| with d ~ N(0, 2σ²), adjacent d correlated −1/2).
_VAR_MR = 2.0 - 4.0 / math.pi
_COV_MR = 4.0 / math.pi * (math.sqrt(0.75) + math.pi / 12.0 - 1.0)


@dataclass(frozen=True, slots=True, kw_only=True)
class IndexEstimate:
    """One capability index with its confidence interval.

    ``value`` is None when the index is undefined (Cp and Pp need both limits).
    """

    name: str
    value: float | None
    low: float | None
    high: float | None
    method: str
    n: int

    def to_dict(self) -> dict[str, object]:
        """Full precision, JSON-ready."""
        return {"name": self.name, "value": self.value, "low": self.low, "high": self.high,
                "method": self.method, "n": self.n}


@dataclass(frozen=True, slots=True, kw_only=True)
class Capability:
    """Cp, Cpk, Pp, Ppk of one series against its specification limits."""

    n: int
    mean: float
    sigma_within: float
    sigma_overall: float
    dof_within: float
    dof_overall: float
    lower_limit: float | None
    upper_limit: float | None
    confidence: float
    cp: IndexEstimate
    cpk: IndexEstimate
    pp: IndexEstimate
    ppk: IndexEstimate

    def to_dict(self) -> dict[str, object]:
        """Full precision, JSON-ready."""
        return {
            "n": self.n, "mean": self.mean, "sigma_within": self.sigma_within,
            "sigma_overall": self.sigma_overall, "dof_within": self.dof_within,
            "dof_overall": self.dof_overall, "lower_limit": self.lower_limit,
            "upper_limit": self.upper_limit, "confidence": self.confidence,
            "cp": self.cp.to_dict(), "cpk": self.cpk.to_dict(),
            "pp": self.pp.to_dict(), "ppk": self.ppk.to_dict(),
        }


def moving_ranges(values: ArrayLike) -> NDArray[np.float64]:
    """``|x_i − x_{i−1}|`` for i = 1 … n−1."""
    x = np.asarray(values, dtype=float)
    return np.abs(np.diff(x))


def sigma_within(values: ArrayLike) -> float:
    """Short-term σ from the average moving range: ``MR̄ / d2`` (d2 = 1.128)."""
    mr = moving_ranges(values)
    if mr.size == 0:
        raise InputError("within-σ needs at least 2 values (one moving range)")
    return float(mr.mean() / D2)


def mr_sigma_dof(n: int) -> float:
    """Effective degrees of freedom of ``MR̄/d2`` from ``n`` individuals.

    Matches ``Var(σ̂)/σ² ≈ 1/(2ν)`` (the χ² approximation) with the exact variance of the
    mean of ``k = n − 1`` span-2 moving ranges of normal data (adjacent ranges correlate):
    ``Var(MR̄)/σ² = [k·v + 2(k−1)·c] / k²``; ν ≈ 0.605·(n − 1) for large n.
    """
    if n < 2:
        raise InputError(f"within-σ needs at least 2 values, got {n}")
    k = n - 1
    relative_var = (k * _VAR_MR + 2 * (k - 1) * _COV_MR) / (k * k) / (4.0 / math.pi)
    return 1.0 / (2.0 * relative_var)


def cp_interval(value: float, dof: float, confidence: float) -> tuple[float, float]:
    """χ² interval for Cp or Pp: ``Ĉp·√(χ²_{α/2,ν}/ν) ≤ Cp ≤ Ĉp·√(χ²_{1−α/2,ν}/ν)``.

    Parameters
    ----------
    value : float
        The estimate Ĉp.
    dof : float
        Degrees of freedom ν of the σ estimate (n − 1 for the sample standard deviation).
    confidence : float
        Two-sided level, e.g. 0.95.
    """
    alpha = 1.0 - confidence
    low = value * math.sqrt(float(stats.chi2.ppf(alpha / 2, dof)) / dof)
    high = value * math.sqrt(float(stats.chi2.ppf(1 - alpha / 2, dof)) / dof)
    return low, high


def cpk_interval(value: float, n: int, dof: float, confidence: float) -> tuple[float, float]:
    """Bissell's (1990) normal approximation for Cpk or Ppk.

    ``Ĉpk·[1 ± z_{α/2}·√(1/(9nĈpk²) + 1/(2ν))]``, written as
    ``Ĉpk ± z·√(1/(9n) + Ĉpk²/(2ν))`` so that it stays finite at Ĉpk = 0.
    """
    z = float(stats.norm.ppf(1 - (1.0 - confidence) / 2))
    half = z * math.sqrt(1.0 / (9.0 * n) + value * value / (2.0 * dof))
    return value - half, value + half


def capability(
    values: ArrayLike,
    *,
    lower_limit: float | None,
    upper_limit: float | None,
    confidence: float = 0.95,
) -> Capability:
    """Cp, Cpk, Pp, Ppk of ``values`` against the specification limits.

    Parameters
    ----------
    values : array_like
        The individual results in time order (the order matters for the moving ranges).
    lower_limit, upper_limit : float or None
        Specification limits; with one of them None, Cp and Pp are undefined and Cpk/Ppk are
        the one-sided index of the other.
    confidence : float
        Two-sided confidence level of the intervals.

    Returns
    -------
    Capability
        Within σ = MR̄/d2 (ν from :func:`mr_sigma_dof`), overall σ = s (ν = n − 1); Cp/Pp
        intervals by χ², Cpk/Ppk by Bissell's approximation.

    Raises
    ------
    InputError
        Fewer than 2 values, no limit at all, limits crossed, a zero spread, or a
        confidence outside (0, 1).
    """
    x = np.asarray(values, dtype=float)
    n = int(x.size)
    if n < 2:
        raise InputError(f"capability needs at least 2 values, got {n}")
    if not np.all(np.isfinite(x)):
        raise InputError("capability: a value is not finite")
    if lower_limit is None and upper_limit is None:
        raise InputError("capability needs a lower or an upper specification limit")
    if lower_limit is not None and upper_limit is not None and upper_limit <= lower_limit:
        raise InputError(f"upper limit {upper_limit} is not above lower limit {lower_limit}")
    if not 0.0 < confidence < 1.0:
        raise InputError(f"confidence must lie in (0, 1), got {confidence}")
    mean = float(x.mean())
    s_within = sigma_within(x)
    s_overall = float(x.std(ddof=1))
    if s_within <= 0.0 or s_overall <= 0.0:
        raise InputError("capability: the values do not vary (σ = 0)")
    dof_w, dof_o = mr_sigma_dof(n), float(n - 1)
    within = "σ = MR̄/d2"
    overall = "σ = s (n − 1)"
    return Capability(
        n=n, mean=mean, sigma_within=s_within, sigma_overall=s_overall,
        dof_within=dof_w, dof_overall=dof_o, lower_limit=lower_limit,
        upper_limit=upper_limit, confidence=confidence,
        cp=_cp("Cp", x, lower_limit, upper_limit, s_within, dof_w, confidence, within),
        cpk=_cpk("Cpk", mean, n, lower_limit, upper_limit, s_within, dof_w, confidence,
                 within),
        pp=_cp("Pp", x, lower_limit, upper_limit, s_overall, dof_o, confidence, overall),
        ppk=_cpk("Ppk", mean, n, lower_limit, upper_limit, s_overall, dof_o, confidence,
                 overall),
    )


def _cp(name: str, x: NDArray[np.float64], lower: float | None, upper: float | None,
        sigma: float, dof: float, confidence: float, how: str) -> IndexEstimate:
    n = int(x.size)
    if lower is None or upper is None:
        return IndexEstimate(name=name, value=None, low=None, high=None,
                             method="undefined with one specification limit", n=n)
    value = (upper - lower) / (6.0 * sigma)
    low, high = cp_interval(value, dof, confidence)
    return IndexEstimate(name=name, value=value, low=low, high=high,
                         method=f"χ² interval, ν = {dof:.1f}; {how}", n=n)


def _cpk(name: str, mean: float, n: int, lower: float | None, upper: float | None,
         sigma: float, dof: float, confidence: float, how: str) -> IndexEstimate:
    sides = [(upper - mean) if upper is not None else math.inf,
             (mean - lower) if lower is not None else math.inf]
    value = min(sides) / (3.0 * sigma)
    low, high = cpk_interval(value, n, dof, confidence)
    return IndexEstimate(name=name, value=value, low=low, high=high,
                         method=f"Bissell (1990) normal approximation, ν = {dof:.1f}; {how}",
                         n=n)
