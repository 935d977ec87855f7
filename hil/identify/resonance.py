"""Two-mass resonance from a measured FRF: a periodic multisine's lines or a stepped sine.

**Multisine** (:func:`frf_lines`): every line is a harmonic of the period, so each period's
Fourier coefficients of position ``P``, reported torque ``T`` and velocity command ``V`` are
exact (:func:`hil.identify.multisine.period_phasors`); per line the FRF is H1 over the
periods, its standard error the delete-one-period jackknife's, and the coherence is taken
over the periods as below.

**Stepped sine** (:func:`frf_point`): each frequency (velocity mode, on a constant-speed
carrier so friction stays linear) is cut into blocks of whole periods; per block the
orthogonal correlation gives the phasors of the encoder position ``P``, the reported torque
``T`` and the velocity command ``V``. Per frequency: the FRF ``P/T`` (H1:
``Σ P·T* / Σ |T|²``), its relative standard error (block scatter) and the coherence
``γ² = |Σ P·T*|² / (Σ|P|²·Σ|T|²)`` over the blocks.

The fitted model is the motor side of a two-mass axis, with the current-loop lag and the
drive's zero-order hold (exact sampled-data response, as in :mod:`hil.identify.current_loop`):

    P/T = (s²/ω_a² + 2ζ_a·s/ω_a + 1) / (s²/ω_r² + 2ζ_r·s/ω_r + 1) / (J·s·(s + B/J)·(τ·s + 1))

with anti-resonance ω_a (load alone on the shaft), resonance ω_r (both masses against the
shaft), J the total inertia. Weighted complex least squares on the points' standard errors;
parameter uncertainties from the fit covariance, scaled by ``√(χ²/ν)`` when above one.
The velocity loop's bandwidth is where the closed-loop ``|jω·P / V|`` first falls below
``1/√2`` (log-interpolated); the article's rule wants ``f_r ≥ 5 ×`` that.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from hil.errors import IdentificationError
from hil.identify.current_loop import IMAGES, block_phasors
from hil.identify.estimate import TYPE_A_SOURCE, Component, Estimate, with_budget
from hil.identify.multisine import jackknife, period_phasors

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]
HALF_POWER = 1.0 / math.sqrt(2.0)


@dataclass(frozen=True, slots=True, kw_only=True)
class TwoMassModel:
    """The motor side of a two-mass axis with the current-loop lag (module docstring).

    Attributes
    ----------
    inertia_kg_m2 : float
        J, the total inertia (kg·m²).
    antiresonance_hz, antiresonance_damping : float
        f_a (Hz) and ζ_a.
    resonance_hz, resonance_damping : float
        f_r (Hz) and ζ_r.
    viscous_over_inertia_1_s : float
        B/J (1/s).
    time_constant_s : float
        τ, the current loop's time constant (s).
    """

    inertia_kg_m2: float  # total
    antiresonance_hz: float
    antiresonance_damping: float
    resonance_hz: float
    resonance_damping: float
    viscous_over_inertia_1_s: float
    time_constant_s: float  # current loop

    def as_vector(self) -> FloatArray:
        """The fit's parameter vector.

        Returns
        -------
        ndarray, shape (7,)
            Natural logarithms of the fields in declaration order, B/J taken as at least
            1e-3 1/s and τ as at least 1e-6 s.
        """
        return np.log([self.inertia_kg_m2, self.antiresonance_hz, self.antiresonance_damping,
                       self.resonance_hz, self.resonance_damping,
                       max(self.viscous_over_inertia_1_s, 1e-3), max(self.time_constant_s, 1e-6)])

    @classmethod
    def from_vector(cls, x: FloatArray) -> TwoMassModel:
        """The model from a parameter vector.

        Parameters
        ----------
        x : array, shape (7,)
            Logarithms of the fields, as :meth:`as_vector` gives them.

        Returns
        -------
        TwoMassModel
        """
        v = np.exp(x)
        return cls(inertia_kg_m2=float(v[0]), antiresonance_hz=float(v[1]),
                   antiresonance_damping=float(v[2]), resonance_hz=float(v[3]),
                   resonance_damping=float(v[4]), viscous_over_inertia_1_s=float(v[5]),
                   time_constant_s=float(v[6]))


def two_mass_response(model: TwoMassModel, frequency_hz: FloatArray, *, fs_hz: float
                      ) -> ComplexArray:
    """Sampled position over held torque of ``model`` (exact zero-order-hold response).

    Parameters
    ----------
    model : TwoMassModel
        The model.
    frequency_hz : array
        Frequencies (Hz), below ``fs_hz/2``.
    fs_hz : float
        The sample rate (Hz): the hold period and the aliases summed.

    Returns
    -------
    ndarray of complex, shape (len(frequency_hz),)
        The response (rad/N·m).
    """
    omega = 2 * math.pi * np.atleast_1d(np.asarray(frequency_hz, dtype=np.float64))
    images = 2 * math.pi * fs_hz * np.arange(-IMAGES, IMAGES + 1)
    s = 1j * (omega[:, None] + images[None, :])
    wa, wr = 2 * math.pi * model.antiresonance_hz, 2 * math.pi * model.resonance_hz
    zeros = (s / wa) ** 2 + 2 * model.antiresonance_damping * s / wa + 1.0
    poles = (s / wr) ** 2 + 2 * model.resonance_damping * s / wr + 1.0
    rigid = 1.0 / (s * (s + model.viscous_over_inertia_1_s) * (model.time_constant_s * s + 1))
    total = np.sum(zeros / poles * rigid / s, axis=1)
    hold = (1.0 - np.exp(-1j * omega / fs_hz)) * fs_hz
    return np.asarray(hold * total / model.inertia_kg_m2, dtype=np.complex128)


@dataclass(frozen=True, slots=True, kw_only=True)
class FrfPoint:
    """One frequency of the FRF (a stepped-sine frequency or a multisine line).

    Attributes
    ----------
    frequency_hz : float
        The sine's frequency (Hz).
    frf_rad_nm : complex
        P/T (rad/N·m), H1 over the blocks: ``Σ P·T* / Σ |T|²``.
    relative_u : float
        Standard error of the mean of the block ratios P/T (their complex scatter),
        relative to ``|frf_rad_nm|``.
    coherence : float
        γ² over the blocks, 1 for a perfectly linear noise-free response.
    closed_loop : complex
        ``jω·P / V``, motor velocity over velocity command, the mean over the blocks.
    blocks : int
        Blocks of whole periods used (a multisine: its analysed periods).
    closed_loop_relative_u : float
        Standard error of ``|closed_loop|`` (block scatter, or the jackknife over periods),
        relative to it: the loop's own noise moves the bandwidth from run to run.
    """

    frequency_hz: float
    frf_rad_nm: complex  # P/T, H1 over the blocks: Σ P·T* / Σ |T|²
    relative_u: float  # standard error of |P/T| relative to |P/T| (block scatter)
    coherence: float  # γ² over the blocks, 1 for a perfectly linear noise-free response
    closed_loop: complex  # jω·P / V (motor velocity over velocity command)
    blocks: int
    closed_loop_relative_u: float = 0.0  # standard error of |closed_loop|, relative


def frf_point(time_s: FloatArray, position_rad: FloatArray, torque_nm: FloatArray,
              command_rad_s: FloatArray, *, frequency_hz: float, fs_hz: float,
              blocks: int) -> FrfPoint:
    """One stepped-sine frequency (settled samples, whole periods) → :class:`FrfPoint`.

    Parameters
    ----------
    time_s, position_rad, torque_nm, command_rad_s : array
        Samples of the segment: time (s), encoder position (rad), reported torque (N·m)
        and velocity command (rad/s).
    frequency_hz : float
        The sine's frequency (Hz).
    fs_hz : float
        The recording's sample rate (Hz).
    blocks : int
        Number of blocks of whole periods the segment is cut into (≥ 2; at most one per
        whole period).

    Returns
    -------
    FrfPoint
        The H1 FRF, its relative standard error, the coherence and the closed loop.

    Raises
    ------
    IdentificationError
        Fewer than two whole periods, or a block without torque at the frequency.
    """
    periods = math.floor((time_s[-1] - time_s[0] + 1.0 / fs_hz) * frequency_hz + 1e-6)
    blocks = min(blocks, periods)
    if blocks < 2:
        raise IdentificationError(f"{frequency_hz:g} Hz: {periods} periods, need 2 blocks")
    omega = 2 * math.pi * frequency_hz
    per_block = periods // blocks
    edges = np.searchsorted(
        time_s - time_s[0], np.arange(blocks + 1) * per_block / frequency_hz - 0.5 / fs_hz)
    p_hat, t_hat, v_hat = [], [], []
    for a, b in itertools.pairwise(edges):
        p, t, v = block_phasors(time_s[a:b], [position_rad[a:b], torque_nm[a:b],
                                              command_rad_s[a:b]], omega=omega)
        p_hat.append(p)
        t_hat.append(t)
        v_hat.append(v)
    p_arr, t_arr, v_arr = np.asarray(p_hat), np.asarray(t_hat), np.asarray(v_hat)
    if np.any(t_arr == 0):
        raise IdentificationError(f"{frequency_hz:g} Hz: no torque at the frequency")
    ratios = p_arr / t_arr
    closed = 1j * omega * p_arr / v_arr  # per block
    mean = complex(np.sum(p_arr * np.conj(t_arr)) / np.sum(np.abs(t_arr) ** 2))  # H1
    cross = abs(np.sum(p_arr * np.conj(t_arr))) ** 2
    coherence = float(cross / (np.sum(np.abs(p_arr) ** 2) * np.sum(np.abs(t_arr) ** 2)))
    return FrfPoint(
        frequency_hz=frequency_hz, frf_rad_nm=mean,
        relative_u=float(np.std(ratios, ddof=1) / math.sqrt(blocks) / abs(mean)),
        coherence=coherence, closed_loop=complex(np.mean(closed)), blocks=blocks,
        closed_loop_relative_u=float(np.std(np.abs(closed), ddof=1) / math.sqrt(blocks)
                                     / abs(np.mean(closed))))


def frf_lines(position_rad: FloatArray, torque_nm: FloatArray, command_rad_s: FloatArray, *,
              harmonics: Sequence[int], period_s: float, fs_hz: float,
              periods: int) -> list[FrfPoint]:
    """One :class:`FrfPoint` per multisine line from the analysed periods.

    Parameters
    ----------
    position_rad, torque_nm, command_rad_s : array
        Encoder position (rad), reported torque (N·m) and velocity command (rad/s) over the
        analysed periods (settling dropped), one sample per control period.
    harmonics : sequence of int
        The lines (cycles per period), increasing.
    period_s, fs_hz : float
        The period (s; a whole number of samples) and the sample rate (Hz).
    periods : int
        Analysed periods (at least 3: the jackknife leaves one out).

    Returns
    -------
    list of FrfPoint
        Per line: H1 ``Σ P·T* / Σ|T|²`` over the periods, the jackknife standard error of H1
        relative to ``|H1|``, γ² over the periods, and ``jω·ΣP / ΣV``.

    Raises
    ------
    IdentificationError
        Fewer than 3 periods, fewer samples than the periods need, or a line without
        torque in some period.
    """
    n = round(period_s * fs_hz)
    if periods < 3:
        raise IdentificationError(f"{periods} analysed periods, need at least 3")
    if min(len(position_rad), len(torque_nm), len(command_rad_s)) < n * periods:
        raise IdentificationError(f"the recording holds fewer than {periods} periods of {n} "
                                  "samples after the settling")
    p, t, v = (period_phasors(x, period_samples=n, periods=periods, harmonics=harmonics)
               for x in (position_rad, torque_nm, command_rad_s))
    if np.any(t == 0):
        raise IdentificationError("a multisine line without torque in some period")
    cross, power = p * np.conj(t), np.abs(t) ** 2  # (periods, lines)
    h1 = cross.sum(axis=0) / power.sum(axis=0)
    left_out = (cross.sum(axis=0) - cross) / (power.sum(axis=0) - power)  # H1 without p
    se = np.hypot(jackknife(left_out.real, h1.real)[1], jackknife(left_out.imag, h1.imag)[1])
    coherence = np.abs(cross.sum(axis=0)) ** 2 / (
        np.sum(np.abs(p) ** 2, axis=0) * power.sum(axis=0))
    frequency_hz = np.asarray(harmonics, dtype=np.float64) / period_s
    closed = 2j * math.pi * frequency_hz * p.sum(axis=0) / v.sum(axis=0)
    closed_left_out = np.abs(2j * math.pi * frequency_hz * (p.sum(axis=0) - p)
                             / (v.sum(axis=0) - v))
    closed_se = jackknife(closed_left_out, np.abs(closed))[1]
    return [FrfPoint(frequency_hz=float(f), frf_rad_nm=complex(h1[k]),
                     relative_u=float(se[k] / abs(h1[k])), coherence=float(coherence[k]),
                     closed_loop=complex(closed[k]), blocks=periods,
                     closed_loop_relative_u=float(closed_se[k] / abs(closed[k])))
            for k, f in enumerate(frequency_hz)]


@dataclass(frozen=True, slots=True, kw_only=True)
class ResonanceResult:
    """The two-mass fit to a measured FRF.

    Attributes
    ----------
    points : tuple of FrfPoint
        The FRF fitted.
    model : TwoMassModel
        The fitted model.
    resonance : Estimate
        ``resonance_frequency_hz``: f_r (Hz).
    antiresonance : Estimate
        ``antiresonance_frequency_hz``: f_a (Hz).
    damping : Estimate
        ``resonance_damping_ratio``: ζ_r.
    bandwidth_hz : float
        The velocity loop's bandwidth, −3 dB of the closed loop (Hz).
    ratio : Estimate
        ``resonance_to_bandwidth_ratio``: f_r over the bandwidth.
    chi2_per_dof : float
        χ² of the fit per degree of freedom (2 × frequencies − 7).
    """

    points: tuple[FrfPoint, ...]
    model: TwoMassModel
    resonance: Estimate  # resonance_frequency_hz
    antiresonance: Estimate  # antiresonance_frequency_hz
    damping: Estimate  # resonance_damping_ratio
    bandwidth_hz: float  # velocity loop, −3 dB of the closed loop
    ratio: Estimate  # resonance_to_bandwidth_ratio
    chi2_per_dof: float


def velocity_loop_bandwidth_hz(points: Sequence[FrfPoint]) -> float:
    """First frequency where ``|closed loop|`` falls below 1/√2 (log-log interpolation).
    :func:`bandwidth_relative_u` is its uncertainty.

    Parameters
    ----------
    points : sequence of FrfPoint
        The FRF, in increasing frequency.

    Returns
    -------
    float
        The velocity loop's −3 dB bandwidth (Hz).

    Raises
    ------
    IdentificationError
        No point falls below 1/√2, or the first already does.
    """
    (x0, x1), (y0, y1), _ = _crossing(points)
    return float(np.exp(x0 + (math.log(HALF_POWER) - y0) * (x1 - x0) / (y1 - y0)))


def _crossing(points: Sequence[FrfPoint]) -> tuple[tuple[float, float], tuple[float, float],
                                                   int]:
    """``ln f`` and ``ln|T|`` of the two lines about the first fall below 1/√2, and the
    index of the second.

    Raises
    ------
    IdentificationError
        No point falls below 1/√2, or the first already does.
    """
    freqs = np.array([p.frequency_hz for p in points])
    gain = np.abs([p.closed_loop for p in points])
    below = np.flatnonzero(gain < HALF_POWER)
    if below.size == 0 or below[0] == 0:
        raise IdentificationError("the band does not bracket the velocity loop's -3 dB point")
    k = int(below[0])
    return ((math.log(freqs[k - 1]), math.log(freqs[k])),
            (math.log(gain[k - 1]), math.log(gain[k])), k)


def bandwidth_relative_u(points: Sequence[FrfPoint]) -> float:
    """Relative standard uncertainty of :func:`velocity_loop_bandwidth_hz` from the two
    lines it interpolates between: ``ln f = x₀ + t·(x₁ − x₀)``, ``t = (ln h − y₀)/(y₁ − y₀)``
    with ``y = ln|T|``, so ``u(ln f) = |x₁ − x₀|/|y₁ − y₀|·√((1 − t)²u₀² + t²u₁²)``, ``uᵢ``
    the lines' relative u of ``|T|`` (independent: each line its own jackknife)."""
    (x0, x1), (y0, y1), k = _crossing(points)
    t = (math.log(HALF_POWER) - y0) / (y1 - y0)
    u0, u1 = points[k - 1].closed_loop_relative_u, points[k].closed_loop_relative_u
    return abs(x1 - x0) / abs(y1 - y0) * math.hypot((1 - t) * u0, t * u1)


def _initial_model(points: Sequence[FrfPoint], *, time_constant_s: float) -> TwoMassModel:
    freqs = np.array([p.frequency_hz for p in points])
    normalised = np.abs([p.frf_rad_nm for p in points]) * (2 * math.pi * freqs) ** 2
    k_r = int(np.argmax(normalised))
    if k_r == 0:
        raise IdentificationError("no resonance peak inside the band")
    k_a = int(np.argmin(normalised[: k_r + 1]))
    if k_a == 0:
        raise IdentificationError("no anti-resonance below the resonance inside the band")
    inertia = 1.0 / float(np.median(normalised[: max(k_a // 2, 1)]))
    return TwoMassModel(inertia_kg_m2=inertia, antiresonance_hz=float(freqs[k_a]),
                        antiresonance_damping=0.05, resonance_hz=float(freqs[k_r]),
                        resonance_damping=0.05, viscous_over_inertia_1_s=1.0,
                        time_constant_s=max(time_constant_s, 1e-5))


def identify_resonance(points: Sequence[FrfPoint], *, fs_hz: float,
                       time_constant_s: float = 2e-4) -> ResonanceResult:
    """Fit the two-mass model to a measured frequency response.

    Parameters
    ----------
    points : sequence of FrfPoint
        The measured FRF (:func:`frf_lines` or :func:`frf_point`), at least 6 frequencies.
    fs_hz : float
        The recording's sample rate (Hz): the model's zero-order hold and its images.
    time_constant_s : float
        Start value of the current-loop lag (s; the current-loop protocol's τ when
        measured).

    Returns
    -------
    ResonanceResult
        f_res, f_anti, damping and f_res over the velocity-loop bandwidth as estimates, the
        fitted :class:`TwoMassModel`, the bandwidth, the points and the fit's χ²/dof.
        Uncertainties from the fit covariance scaled by ``√(χ²/ν)``: below one the
        residual's scatter is the noise (the per-period jackknife that weights the lines
        also counts cogging that averages out over the run); above one the excess is a
        Type B line (the model's misfit to this unit). The ratio's from f_r's and a Type A
        line of the bandwidth's (:func:`bandwidth_relative_u`, scaled as f_r's by
        ``√min(χ²/ν, 1)``: the per-period jackknife also counts the cogging each period
        meets at its own place, the same on every run over the same path).

    Raises
    ------
    IdentificationError
        Fewer than 6 points, no resonance peak or anti-resonance below it inside the band,
        a failed fit or one without ``f_first < f_a < f_r``, or a band that does not
        bracket the velocity loop's −3 dB point.
    """
    if len(points) < 6:
        raise IdentificationError(f"{len(points)} frequencies, need at least 6")
    freqs = np.array([p.frequency_hz for p in points])
    measured = np.array([p.frf_rad_nm for p in points])
    sigma = np.array([max(p.relative_u, 1e-4) for p in points]) * np.abs(measured)

    def residual(x: FloatArray) -> FloatArray:
        model = two_mass_response(TwoMassModel.from_vector(x), freqs, fs_hz=fs_hz)
        r = (model - measured) / sigma
        return np.concatenate([r.real, r.imag])

    start = _initial_model(points, time_constant_s=time_constant_s)
    fit = least_squares(residual, start.as_vector(), x_scale=1.0, method="lm")
    model = TwoMassModel.from_vector(fit.x)
    if not fit.success or not (freqs[0] < model.antiresonance_hz < model.resonance_hz):
        raise IdentificationError(f"two-mass fit failed ({fit.message}); "
                                  f"f_a={model.antiresonance_hz:.3g} f_r={model.resonance_hz:.3g}")
    dof = 2 * len(points) - fit.x.size
    chi2_per_dof = float(np.sum(fit.fun**2)) / dof
    jacobian = np.asarray(fit.jac, dtype=np.float64)
    # pseudo-inverse: a nuisance parameter (B/J, τ) driven to zero leaves a flat direction
    log_u = np.sqrt(np.diag(np.linalg.pinv(jacobian.T @ jacobian)))  # relative, at the noise
    bandwidth = velocity_loop_bandwidth_hz(points)
    ratio = model.resonance_hz / bandwidth

    def estimate(name: str, value: float, index: int, unit: str) -> Estimate:
        # the scatter about the two-mass model beyond the FRF's noise is the model's misfit
        # to this unit, the same on every run: a Type B line of its own, not more noise;
        # below the per-period noise (χ²/ν < 1: cogging that differs between periods
        # averages out over the run) the residual's scatter is the noise
        u = value * float(log_u[index]) * math.sqrt(min(chi2_per_dof, 1.0))
        lines = [Component(source=TYPE_A_SOURCE, kind="A", standard_uncertainty=u, unit=unit,
                           dof=float(dof))]
        if chi2_per_dof > 1.0:
            lines.append(Component(
                source=f"two-mass model's misfit to this unit (χ²/ν = {chi2_per_dof:.3g})",
                kind="B", standard_uncertainty=u * math.sqrt(chi2_per_dof - 1.0), unit=unit))
        return with_budget(Estimate(name=name, value=value, standard_uncertainty=u, unit=unit),
                           lines, value=value)

    return ResonanceResult(
        points=tuple(points), model=model, chi2_per_dof=chi2_per_dof, bandwidth_hz=bandwidth,
        resonance=estimate("resonance_frequency_hz", model.resonance_hz, 3, "Hz"),
        antiresonance=estimate("antiresonance_frequency_hz", model.antiresonance_hz, 1, "Hz"),
        damping=estimate("resonance_damping_ratio", model.resonance_damping, 4, "1"),
        ratio=estimate("resonance_to_bandwidth_ratio", ratio, 3, "1").with_components(
            Component(source="velocity-loop bandwidth, from the jackknife of |T| at the two "
                             "lines about its −3 dB point (Type A)", kind="A",
                      standard_uncertainty=ratio * bandwidth_relative_u(points)
                      * math.sqrt(min(chi2_per_dof, 1.0)), unit="1",
                      dof=float(points[0].blocks - 1))),
    )
