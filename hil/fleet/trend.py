"""``trend PARAM``: every stored result of one parameter in time order."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime

from hil.errors import InputError
from hil.fleet.fmt import at_u, typical_u
from hil.fleet.series import SeriesPoint, ordered, single_unit, values_of
from hil.fleet.spc import no_spread_sentence
from hil.gum import rounded_pair


@dataclass(frozen=True, slots=True, kw_only=True)
class TrendResult:
    """The rows of ``trend PARAM``: :meth:`table` for a person, :meth:`to_json` for tools."""

    parameter: str
    unit: str
    points: list[SeriesPoint]

    def table(self) -> str:
        """One line per run; ``value ± U`` rounded as GUM 7.2.6 asks."""
        head = (f"{'started':<22}{'serial':<14}{'station':<12}{'value':>14}{'U':>10}  "
                f"{'outcome':<10}limits")
        lines = [f"trend {self.parameter}{f' ({self.unit})' if self.unit else ''}: "
                 f"{len(self.points)} runs; value ± U (k ≈ 2) as GUM 7.2.6 rounds it", head]
        for p in self.points:
            value, u = rounded_pair(p.value, p.expanded_uncertainty)
            low = at_u(p.lower_limit, p.expanded_uncertainty)
            high = at_u(p.upper_limit, p.expanded_uncertainty)
            lines.append(f"{p.started_at:%Y-%m-%d %H:%M %Z}".ljust(22)
                         + f"{p.serial:<14}{p.station:<12}{value:>14}{u:>10}  "
                         f"{p.outcome:<10}[{low}, {high}]"
                         + ("  reference" if p.is_reference else ""))
        if self.no_spread:
            lines.append(self.no_spread[0].upper() + self.no_spread[1:] + ".")
        return "\n".join(lines)

    @property
    def no_spread(self) -> str:
        """The sentence for a series of two or more runs whose values are all equal, else ""."""
        values = values_of(self.points)
        if values.size < 2:
            return ""
        u = typical_u([p.expanded_uncertainty for p in self.points])
        return no_spread_sentence(values, unit=self.unit, expanded_uncertainty=u)

    def to_json(self) -> dict[str, object]:
        """Full precision."""
        return {"parameter": self.parameter, "unit": self.unit,
                "no_spread": self.no_spread or None,
                "points": [point_dict(p) for p in self.points]}


def point_dict(p: SeriesPoint) -> dict[str, object]:
    """A point's attributes, JSON-ready (``started_at`` in ISO 8601)."""
    return {"run_id": p.run_id, "certificate_id": p.certificate_id, "serial": p.serial,
            "station": p.station, "started_at": p.started_at.isoformat(),
            "value": float(p.value), "standard_uncertainty": float(p.standard_uncertainty),
            "expanded_uncertainty": float(p.expanded_uncertainty), "unit": p.unit,
            "nominal": p.nominal, "lower_limit": p.lower_limit, "upper_limit": p.upper_limit,
            "outcome": p.outcome, "is_reference": bool(p.is_reference)}


def trend_table(points: Sequence[SeriesPoint], *, parameter: str = "value",
                station: str | None = None, since: datetime | None = None,
                include_reference: bool = False) -> TrendResult:
    """The series of one parameter, optionally one station's and from a date on.

    Parameters
    ----------
    points : sequence of SeriesPoint
        The parameter's results, any order.
    station : str, optional
        Keep this station's runs only.
    since : datetime, optional
        Keep runs started at or after it (compare like with like: aware or naive).
    include_reference : bool
        Keep reference (golden) units.
    """
    if since is not None and points and (
            (since.tzinfo is None) != (points[0].started_at.tzinfo is None)):
        raise InputError(f"since {since.isoformat()}: give a time zone exactly when the "
                         "stored runs have one")
    kept = [p for p in points
            if (station is None or p.station == station)
            and (since is None or p.started_at >= since)]
    runs = ordered(kept, include_reference=include_reference)
    return TrendResult(parameter=parameter, unit=single_unit(runs), points=runs)
