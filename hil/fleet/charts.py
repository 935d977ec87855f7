"""Individuals / moving-range chart limits and the EWMA chart (docs/fleet.md §2, §4)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hil.errors import InputError
from hil.fleet.capability import D2, D4, moving_ranges


@dataclass(frozen=True, slots=True, kw_only=True)
class ImrLimits:
    """Centre lines and 3σ limits of an individuals (I) and moving-range (MR) chart.

    ``sigma`` is MR̄/d2; ``source`` says where they come from: ``"data"`` (trial limits
    from the series itself) or ``"baseline"`` (frozen).
    """

    centre: float
    sigma: float
    ucl: float
    lcl: float
    mr_centre: float
    mr_ucl: float
    n: int
    source: str

    def to_dict(self) -> dict[str, object]:
        """Full precision, JSON-ready."""
        return {"centre": self.centre, "sigma": self.sigma, "ucl": self.ucl, "lcl": self.lcl,
                "mr_centre": self.mr_centre, "mr_ucl": self.mr_ucl, "mr_lcl": 0.0,
                "n": self.n, "source": self.source}


def imr_limits_from(centre: float, mr_bar: float, *, n: int, source: str) -> ImrLimits:
    """I chart ``centre ± 3·MR̄/d2``; MR chart centre MR̄, UCL ``D4·MR̄``, LCL 0."""
    sigma = mr_bar / D2
    return ImrLimits(centre=centre, sigma=sigma, ucl=centre + 3.0 * sigma,
                     lcl=centre - 3.0 * sigma, mr_centre=mr_bar, mr_ucl=D4 * mr_bar, n=n,
                     source=source)


def imr_limits(values: ArrayLike) -> ImrLimits:
    """Trial I-MR limits from the series itself.

    Parameters
    ----------
    values : array_like
        Individual results in time order, at least 2.

    Returns
    -------
    ImrLimits
        Centre x̄, σ = MR̄/d2, limits x̄ ± 3σ; MR chart MR̄ and D4·MR̄.
    """
    x = np.asarray(values, dtype=float)
    if x.size < 2:
        raise InputError(f"an individuals chart needs at least 2 values, got {x.size}")
    return imr_limits_from(float(x.mean()), float(moving_ranges(x).mean()), n=int(x.size),
                           source="data")


@dataclass(frozen=True, slots=True, kw_only=True)
class EwmaSettings:
    """EWMA weight λ (0 < λ ≤ 1) and limit width L (in σ of the EWMA statistic)."""

    lam: float = 0.2
    width: float = 3.0

    def __post_init__(self) -> None:
        if not 0.0 < self.lam <= 1.0:
            raise InputError(f"EWMA λ must lie in (0, 1], got {self.lam}")
        if not self.width > 0.0:
            raise InputError(f"EWMA limit width L must be positive, got {self.width}")


@dataclass(frozen=True, slots=True, kw_only=True)
class EwmaChart:
    """The EWMA statistic with its exact, time-varying limits and the points beyond them."""

    lam: float
    width: float
    centre: float
    sigma: float
    z: NDArray[np.float64]
    ucl: NDArray[np.float64]
    lcl: NDArray[np.float64]
    signals: list[int]

    def to_dict(self) -> dict[str, object]:
        """Full precision, JSON-ready."""
        return {"lambda": self.lam, "L": self.width, "centre": self.centre,
                "sigma": self.sigma, "z": self.z.tolist(), "ucl": self.ucl.tolist(),
                "lcl": self.lcl.tolist(), "signals": list(self.signals)}


def ewma_chart(values: ArrayLike, *, centre: float, sigma: float,
               settings: EwmaSettings) -> EwmaChart:
    """EWMA ``z_i = λx_i + (1 − λ)z_{i−1}``, ``z_0 = centre``, with exact limits.

    Parameters
    ----------
    values : array_like
        Individual results in time order.
    centre : float
        Target / in-control mean μ₀ (also z₀).
    sigma : float
        In-control σ of one individual.
    settings : EwmaSettings
        λ and L.

    Returns
    -------
    EwmaChart
        Limits ``μ₀ ± L·σ·√(λ/(2−λ)·[1 − (1−λ)^{2i}])`` (i = 1, 2, …); ``signals`` are the
        0-based indices where z lies strictly outside them.
    """
    x = np.asarray(values, dtype=float)
    if not sigma > 0.0 or not math.isfinite(sigma):
        raise InputError(f"EWMA needs a positive σ, got {sigma}")
    lam, width = settings.lam, settings.width
    z = np.empty_like(x)
    previous = centre
    for i, value in enumerate(x):
        previous = lam * value + (1.0 - lam) * previous
        z[i] = previous
    steps = np.arange(1, x.size + 1, dtype=float)
    half = width * sigma * np.sqrt(lam / (2.0 - lam) * (1.0 - (1.0 - lam) ** (2.0 * steps)))
    ucl, lcl = centre + half, centre - half
    signals = [int(i) for i in np.flatnonzero((z > ucl) | (z < lcl))]
    return EwmaChart(lam=lam, width=width, centre=centre, sigma=sigma, z=z, ucl=ucl, lcl=lcl,
                     signals=signals)
