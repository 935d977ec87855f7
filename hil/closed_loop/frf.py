"""The velocity loop's frequency response from a periodic multisine on a constant carrier.

The command is ``r(t) = v₀ + Σ aₖ·cos(2π fₖ t + φₖ)`` with every ``fₖ`` a harmonic of the
period ``T₀`` (Schroeder phases, low crest factor), so each period holds whole cycles of
every line and its Fourier coefficients are exact (no leakage). The carrier keeps the axis
moving one way: friction is a constant, not a reversal. Per period ``p`` and line ``k``
the phasors of the command ``R``, the drive's velocity estimate ``V`` (its feedback) and
its torque command ``U`` give, with ``E = R − V`` (the error the drive's PI sees)::

    T = V/R   closed loop (complementary sensitivity)    S = E/R = 1 − T   sensitivity
    L = V/E   loop gain = C·P with C = U/E (firmware), P = V/U (plant as the loop sees it)

The phase and stability margins are python-control's (:func:`control.stability_margins` on
:func:`control.frd` of the measured ``L``): phase margin at the gain crossover, and the
stability margin ``s_m`` (least distance of ``L`` to −1), whose inverse is the peak of
``|S|`` (the modulus margin). The gain margin is ``−|L|`` at the first crossing of −180°
by the unwrapped phase above the gain crossover, interpolated between the lines
(:func:`first_phase_crossover_margin_db`): a phase that only just reaches −180° at a line
moves that crossing a little from one jackknife replicate to the next, where
python-control's smallest margin over every crossing jumped to a later one (27.5 ± 137 dB
on the demo). The −3 dB bandwidth and the peak of ``|T|`` are read from the measured ``T``
(log-frequency interpolation between lines).

Type A uncertainty: delete-one-period jackknife of every figure (``P − 1`` degrees of
freedom): the data's scatter as these estimators evaluate it.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hil.errors import IdentificationError
from hil.identify.estimate import Estimate
from hil.identify.multisine import jackknife, period_phasors

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

MARGIN_NAMES = ("bandwidth_hz", "peak_gain_db", "gain_margin_db", "phase_margin_deg",
                "sensitivity_peak_db")


@dataclass(frozen=True, slots=True, kw_only=True)
class LoopFigures:
    """What the measured FRFs say about the loop (one set of periods).

    Attributes
    ----------
    bandwidth_hz : float
        First frequency where ``|T|`` falls below −3 dB.
    peak_gain_db : float
        Largest ``|T|`` over the lines (dB).
    gain_margin_db : float
        ``−|L|`` in dB at the phase crossover.
    phase_margin_deg : float
        ``180° + ∠L`` at the gain crossover.
    sensitivity_peak_db : float
        ``1/s_m`` in dB: the peak of ``|S|`` (the modulus margin's inverse).
    """

    bandwidth_hz: float
    peak_gain_db: float
    gain_margin_db: float
    phase_margin_deg: float
    sensitivity_peak_db: float

    def as_tuple(self) -> tuple[float, ...]:
        """The figures in the order of :data:`MARGIN_NAMES`."""
        return (self.bandwidth_hz, self.peak_gain_db, self.gain_margin_db,
                self.phase_margin_deg, self.sensitivity_peak_db)


def minus_3db_bandwidth_hz(frequencies_hz: FloatArray, closed_loop: ComplexArray) -> float:
    """First crossing of ``|T|`` below ``1/√2``, interpolated in dB over log frequency.

    Raises
    ------
    IdentificationError
        ``|T|`` starts below −3 dB or never falls below it in the measured band.
    """
    gain_db = 20 * np.log10(np.abs(closed_loop))
    below = np.flatnonzero(gain_db < -10 * math.log10(2))
    if below.size == 0 or below[0] == 0:
        raise IdentificationError(
            "the closed loop's −3 dB point is outside the measured lines "
            f"({frequencies_hz[0]:.3g}–{frequencies_hz[-1]:.3g} Hz)")
    i = int(below[0])
    x0, x1 = math.log(frequencies_hz[i - 1]), math.log(frequencies_hz[i])
    y0, y1 = gain_db[i - 1], gain_db[i]
    target = -10 * math.log10(2)
    return math.exp(x0 + (target - y0) * (x1 - x0) / (y1 - y0))


def first_phase_crossover_margin_db(frequencies_hz: FloatArray, loop: ComplexArray) -> float:
    """``−20·log10|L|`` where the unwrapped phase of ``L`` first falls through −180° above
    the gain crossover (where ``|L|`` falls below 1: a velocity loop's phase hovers near
    −180° below it, where a gain change does not destabilise), the phase taken in
    (−360°, 0°] at the gain crossover; phase and ``|L|`` in dB interpolated linearly
    between the two lines around the crossing.

    Raises
    ------
    IdentificationError
        ``|L|`` does not fall below 1, or the phase does not reach −180° above that, in
        the measured band.
    """
    gain_db = 20 * np.log10(np.abs(loop))
    crossover = np.flatnonzero(gain_db < 0.0)
    if crossover.size == 0 or crossover[0] == 0:
        raise IdentificationError(
            "the loop gain has no gain crossover between "
            f"{frequencies_hz[0]:.3g} and {frequencies_hz[-1]:.3g} Hz: extend the lines")
    first = int(crossover[0])
    phase_deg = np.degrees(np.unwrap(np.angle(loop)))
    phase_deg -= 360.0 * math.ceil(phase_deg[first] / 360.0)  # (−360°, 0°] there
    below = np.flatnonzero(phase_deg[first:] <= -180.0)
    if below.size == 0:
        raise IdentificationError(
            "the loop gain has no phase crossover above its gain crossover, between "
            f"{frequencies_hz[0]:.3g} and {frequencies_hz[-1]:.3g} Hz: extend the lines")
    i = first + int(below[0])
    fraction = (phase_deg[i - 1] + 180.0) / (phase_deg[i - 1] - phase_deg[i])
    return float(-(gain_db[i - 1] + fraction * (gain_db[i] - gain_db[i - 1])))


def loop_figures(frequencies_hz: FloatArray, command: ComplexArray, velocity: ComplexArray
                 ) -> LoopFigures:
    """Bandwidth, peak gain and margins from averaged phasors of one set of periods.

    Parameters
    ----------
    frequencies_hz : ndarray
        The lines.
    command, velocity : ndarray, complex
        Phasors of the velocity command ``R`` and the drive's velocity estimate ``V``.

    Returns
    -------
    LoopFigures
    """
    closed = velocity / command
    loop = velocity / (command - velocity)
    omega = 2 * math.pi * frequencies_hz
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # no crossover in band: python-control warns, returns inf
        import control  # here: it loads matplotlib.pyplot (0.5 s of every calibration's start)

        _, pm, sm, _, _, _ = control.stability_margins(control.frd(loop, omega))
    if not math.isfinite(pm):
        raise IdentificationError(
            "the loop gain has no gain crossover between "
            f"{frequencies_hz[0]:.3g} and {frequencies_hz[-1]:.3g} Hz: extend the lines")
    return LoopFigures(
        bandwidth_hz=minus_3db_bandwidth_hz(frequencies_hz, closed),
        peak_gain_db=float(20 * np.log10(np.max(np.abs(closed)))),
        gain_margin_db=first_phase_crossover_margin_db(frequencies_hz, loop),
        phase_margin_deg=float(pm),
        sensitivity_peak_db=float(-20 * math.log10(sm)),
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class FrfResult:
    """The velocity loop's measured FRFs and figures with their jackknife uncertainty.

    Attributes
    ----------
    frequencies_hz : ndarray
    closed_loop, sensitivity, loop_gain, controller, plant : ndarray, complex
        ``T``, ``S``, ``L``, ``C = U/E`` and ``P = V/U``, averaged over the periods.
    estimates : dict of str to Estimate
        One per :data:`MARGIN_NAMES`, named ``velocity_<name>``.
    periods : int
    """

    frequencies_hz: FloatArray
    closed_loop: ComplexArray
    sensitivity: ComplexArray
    loop_gain: ComplexArray
    controller: ComplexArray
    plant: ComplexArray
    estimates: dict[str, Estimate]
    periods: int


UNITS = {"bandwidth_hz": "Hz", "peak_gain_db": "dB", "gain_margin_db": "dB",
         "phase_margin_deg": "°", "sensitivity_peak_db": "dB"}


def analyse_frf(
    *, command: FloatArray, velocity: FloatArray, torque: FloatArray, harmonics: Sequence[int],
    period_s: float, fs_hz: float, periods: int,
    figures: Callable[[FloatArray, ComplexArray, ComplexArray], LoopFigures] = loop_figures,
) -> FrfResult:
    """Velocity-loop FRFs and figures from the analysed periods of a multisine run.

    Parameters
    ----------
    command, velocity, torque : ndarray
        Velocity command, the drive's velocity estimate and its torque command over the
        analysed periods (settling periods already dropped), one sample per control period.
    harmonics : sequence of int
        The multisine's lines (cycles per period).
    period_s, fs_hz : float
    periods : int
        Analysed periods (at least 3 for the jackknife).
    figures : callable
        The figures from phasors (default :func:`loop_figures`).

    Returns
    -------
    FrfResult

    Raises
    ------
    IdentificationError
        Fewer than 3 periods, or a figure the data cannot give (no −3 dB point in band).
    """
    if periods < 3:
        raise IdentificationError(f"need at least 3 analysed periods, got {periods}")
    n = round(period_s * fs_hz)
    r = period_phasors(command, period_samples=n, periods=periods, harmonics=harmonics)
    v = period_phasors(velocity, period_samples=n, periods=periods, harmonics=harmonics)
    u = period_phasors(torque, period_samples=n, periods=periods, harmonics=harmonics)
    f = np.asarray(harmonics, dtype=np.float64) / period_s
    rm, vm, um = r.mean(axis=0), v.mean(axis=0), u.mean(axis=0)
    full = np.array(figures(f, rm, vm).as_tuple())
    left_out = np.array([
        figures(f, (rm * periods - r[i]) / (periods - 1),
                (vm * periods - v[i]) / (periods - 1)).as_tuple()
        for i in range(periods)
    ])
    value, se = jackknife(left_out, full)
    estimates = {
        name: Estimate(name=f"velocity_{name}", value=float(value[j]),
                       standard_uncertainty=float(se[j]), unit=UNITS[name], dof=periods - 1)
        for j, name in enumerate(MARGIN_NAMES)
    }
    error = rm - vm
    return FrfResult(
        frequencies_hz=f, closed_loop=vm / rm, sensitivity=error / rm, loop_gain=vm / error,
        controller=um / error, plant=vm / um, estimates=estimates, periods=periods,
    )
