"""Results as the store returns them (``StoredResult``), a plain run row with the attributes
the fleet functions read, and a synthetic fleet with a drift."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime, timedelta

import numpy as np

from hil.store.query import StoredResult as Point


@dataclass(frozen=True)
class Run:
    serial: str
    station: str
    started_at: datetime
    outcome: str
    attempt: int
    aborted: bool
    is_reference: bool
    axis: str = "elevation"


START = datetime(2026, 3, 2, 8, 0, tzinfo=UTC)


def series(values: list[float] | np.ndarray, *, nominal: float = 3.6e-3,
           tolerance: float = 0.1, u: float = 2.0e-5, unit: str = "kg·m²",
           step: timedelta = timedelta(hours=2), stations: tuple[str, ...] = ("ST1", "ST2"),
           reference_every: int = 0) -> list[Point]:
    """One point per value, two hours apart, stations taking turns; with
    ``reference_every = k`` every k-th run is a golden unit."""
    lower, upper = nominal * (1 - tolerance), nominal * (1 + tolerance)
    out = []
    for i, value in enumerate(values):
        reference = reference_every > 0 and i % reference_every == reference_every - 1
        outcome = "PASS" if lower + 2 * u <= value <= upper - 2 * u else (
            "MARGINAL" if lower <= value <= upper else "FAIL")
        out.append(Point(run_id=f"run-{i:04d}", certificate_id=f"CERT-{i:04d}",
                         serial="GOLDEN-1" if reference else f"SN-{i:04d}",
                         station=stations[i % len(stations)], started_at=START + i * step,
                         value=float(value), standard_uncertainty=u / 2,
                         expanded_uncertainty=u, unit=unit, nominal=nominal,
                         lower_limit=lower, upper_limit=upper, outcome=outcome,
                         is_reference=reference))
    return out


def drifting_values(n: int = 60, *, drift_from: int = 35, drift_per_run: float = 0.35,
                    seed: int = 7, nominal: float = 3.6e-3, sigma: float = 3.0e-5
                    ) -> np.ndarray:
    """In control around nominal, then a slow upward drift (in σ per run)."""
    rng = np.random.default_rng(seed)
    x = nominal + sigma * rng.standard_normal(n)
    ramp = np.clip(np.arange(n) - drift_from + 1, 0, None) * drift_per_run * sigma
    return x + ramp


def runs_for(points: list[Point]) -> list[Run]:
    """One run per point, plus a failed first attempt (then a pass) for every 7th unit."""
    runs = []
    for i, p in enumerate(points):
        if i % 7 == 3:
            runs.append(Run(serial=p.serial, station=p.station,
                            started_at=p.started_at - timedelta(minutes=30), outcome="FAIL",
                            attempt=1, aborted=False, is_reference=p.is_reference))
            runs.append(Run(serial=p.serial, station=p.station, started_at=p.started_at,
                            outcome=p.outcome, attempt=2, aborted=False,
                            is_reference=p.is_reference))
        else:
            runs.append(Run(serial=p.serial, station=p.station, started_at=p.started_at,
                            outcome=p.outcome, attempt=1, aborted=False,
                            is_reference=p.is_reference))
    return runs
