"""The shaft of a two-mass axis as the sines take it from the resonance protocol (or, where
that protocol has not run, from the profile's declared modes): the modes the J/B/T_c fit
drives its load with (:func:`hil.identify.two_mass.driven_acceleration`) and their
uncertainties as budget lines."""

from __future__ import annotations

import math
from dataclasses import dataclass

from hil.calibration import CalibrationRun
from hil.identify.two_mass import ShaftModes
from hil.profile import UnitProfile
from hil.suite.needs import Need

#: the resonance protocol's results, in :class:`ShaftModes`' order
RESULTS = ("resonance_frequency_hz", "antiresonance_frequency_hz", "resonance_damping_ratio")
FIELDS = ("resonance_hz", "antiresonance_hz", "damping_ratio")
UNITS = ("Hz", "Hz", "")
SHAFT = Need(protocol="resonance", result=RESULTS[0],
             without="the profile's nominal shaft modes taken out of the sines, their limits "
                     "rectangular budget lines (one rigid inertia where it declares none)")


@dataclass(frozen=True, slots=True, kw_only=True)
class ShaftInput:
    """The shaft's modes, each with its standard uncertainty, and where they came from."""

    modes: ShaftModes
    standard_uncertainties: tuple[float, float, float]  # in RESULTS' order
    measured: bool  # by the resonance protocol; False: the profile's nominal

    def lines(self) -> list[tuple[str, float, str, ShaftModes]]:
        """One budget line per figure with a non-zero u: its source, u, unit and the modes
        with that figure moved by u (for the re-analysis)."""
        origin = ("taken out (resonance)" if self.measured
                  else "not measured: the profile's nominal taken out, its limits (rectangular)")
        return [(f"two-mass shaft: {result} {origin}", u, unit,
                 self.modes.shifted(**{field: u}))
                for result, field, unit, u in zip(RESULTS, FIELDS, UNITS,
                                                  self.standard_uncertainties, strict=True)
                if u > 0]

    def described(self) -> str:
        """One line for the certificate's details."""
        m = self.modes
        return (f"f_r {m.resonance_hz:.4g} Hz, f_a {m.antiresonance_hz:.4g} Hz, "
                f"ζ_r {m.damping_ratio:.3g} ({'measured' if self.measured else 'nominal'})")


def declared_rectangular(profile: UnitProfile, result: str) -> tuple[float, float] | None:
    """The profile's nominal of ``result`` and the standard uncertainty of a rectangular
    distribution over its limits (GUM 4.3.7); ``None`` unless it declares a nominal > 0."""
    spec = profile.measurements.get(result)
    if spec is None or not spec.nominal > 0:
        return None
    half_width = max(spec.upper_limit - spec.nominal, spec.nominal - max(spec.lower_limit, 0))
    return spec.nominal, half_width / math.sqrt(3)


def shaft_input(calibration: CalibrationRun) -> ShaftInput | None:
    """The shaft measured by the resonance protocol earlier in this calibration, else the
    profile's declared modes, else ``None`` (a rigid axis)."""
    found = calibration.results(*RESULTS)
    if found is not None:
        values = tuple(e.value for e in found)
        uncertainties = tuple(e.standard_uncertainty for e in found)
        measured = True
    else:
        declared = [declared_rectangular(calibration.profile, name) for name in RESULTS]
        if any(d is None for d in declared):
            return None
        values = tuple(d[0] for d in declared if d is not None)
        uncertainties = tuple(d[1] for d in declared if d is not None)
        measured = False
    modes = ShaftModes(**dict(zip(FIELDS, values, strict=True)))
    if not modes.load_to_motor_inertia > 0:
        return None
    return ShaftInput(modes=modes, measured=measured,
                      standard_uncertainties=(uncertainties[0], uncertainties[1],
                                              uncertainties[2]))
