"""The shaft of a two-mass axis as the sines take it from the resonance protocol (or, where
that protocol has not run, from the profile's declared modes): the modes the J/B/T_c fit
drives its load with (:func:`hil.identify.two_mass.driven_acceleration`) and their
uncertainties as budget lines."""

from __future__ import annotations

from dataclasses import dataclass

from hil.calibration import CalibrationRun
from hil.identify.two_mass import ShaftModes
from hil.suite.needs import Need, declared_rectangular

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


def shaft_input(calibration: CalibrationRun) -> ShaftInput | None:
    """The shaft measured by the resonance protocol earlier in this calibration, else the
    profile's declared modes, else ``None`` (a rigid axis)."""
    found = calibration.results(*RESULTS)
    measured = found is not None
    pairs = ([(e.value, e.standard_uncertainty) for e in found] if found is not None
             else [declared_rectangular(calibration.profile, name) for name in RESULTS])
    if any(pair is None for pair in pairs):
        return None
    (f_r, u_r), (f_a, u_a), (zeta, u_zeta) = (pair for pair in pairs if pair is not None)
    modes = ShaftModes(resonance_hz=f_r, antiresonance_hz=f_a, damping_ratio=zeta)
    if not modes.load_to_motor_inertia > 0:
        return None
    return ShaftInput(modes=modes, measured=measured,
                      standard_uncertainties=(u_r, u_a, u_zeta))
