"""Text helpers shared by the tables: numbers as a person reads them."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from hil.fleet.capability import IndexEstimate
from hil.gum import rounded_pair


def typical_u(expanded_uncertainties: Sequence[float]) -> float:
    """The median positive, finite U of a series (0 when there is none)."""
    good = [u for u in expanded_uncertainties if math.isfinite(u) and u > 0]
    return float(np.median(good)) if good else 0.0


def at_u(value: float | None, expanded_uncertainty: float) -> str:
    """``value`` to the decimal place GUM rounding gives a result with this U."""
    if value is None:
        return "—"
    return rounded_pair(value, expanded_uncertainty)[0]


def index_text(estimate: IndexEstimate) -> str:
    """``1.41 [1.12, 1.70]`` (two decimals), ``—`` when undefined."""
    if estimate.value is None or estimate.low is None or estimate.high is None:
        return "—"
    return f"{estimate.value:.2f} [{estimate.low:.2f}, {estimate.high:.2f}]"
