"""What a protocol takes from an earlier one: each suite module declares its ``NEEDS``
(protocol, result, what it does without it); the catalogue checks the profile's run order
against them before any motion, and a protocol that runs without one says so on the
certificate (its messages)."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from hil.calibration import CalibrationRun
from hil.identify.estimate import Estimate
from hil.profile import UnitProfile


@dataclass(frozen=True, slots=True, kw_only=True)
class Need:
    """One input from an earlier protocol of the same calibration."""

    protocol: str  # the protocol that provides it
    result: str  # a declared measurement, or a field of that protocol's details
    without: str  # what the protocol does when it is missing (its fallback)

    def met(self, calibration: CalibrationRun) -> bool:
        """The earlier protocol left it in this calibration."""
        details = calibration.details.get(self.protocol)
        return (calibration.result(self.result) is not None
                or (details is not None and hasattr(details, self.result)))

    def read(self, calibration: CalibrationRun) -> Estimate | None:
        """The judged result, ``None`` when the earlier protocol has not measured it."""
        return calibration.result(self.result)

    def fallback_line(self) -> str:
        """The certificate's line for a fallback used."""
        return f"without {self.protocol}'s {self.result}: {self.without}"


def note_fallbacks(calibration: CalibrationRun, protocol: str, needs: Iterable[Need]) -> list[str]:
    """Record on the protocol's certificate entry (its messages) each need this calibration
    has not met, with the fallback used; returns those lines."""
    lines = [need.fallback_line() for need in needs if not need.met(calibration)]
    record = calibration.protocol(protocol)
    record.messages.extend(line for line in lines if line not in record.messages)
    return lines


def declared_rectangular(profile: UnitProfile, result: str) -> tuple[float, float] | None:
    """A need's declared fallback: the profile's nominal of ``result`` and the standard
    uncertainty of a rectangular distribution over its limits (GUM 4.3.7); ``None`` unless
    it declares a nominal > 0."""
    spec = profile.measurements.get(result)
    if spec is None or not spec.nominal > 0:
        return None
    half_width = max(spec.upper_limit - spec.nominal, spec.nominal - max(spec.lower_limit, 0))
    return spec.nominal, half_width / math.sqrt(3)
