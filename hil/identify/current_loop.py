"""Current-loop lag from the phase of the motion against the reported torque at 20–150 Hz.

The drive reports the torque it *commands* (``K_t,nom · i_q,ref``); the shaft moves with the
torque the current loop actually delivers, a first-order lag ``1/(τ·s + 1)`` behind it. At
a few frequencies well above the velocity loop the per-frequency orthogonal correlation of
the encoder position and the reported torque gives the sampled response ``P(ω)/T(ω)``;
its phase, after the exact sampled-data model of the rigid axis, is the current loop's.

Sampled data, exactly: the reported torque at sample ``k`` is held over ``[k, k+1]`` (zero
-order hold) and the position is sampled at the period starts, so the measured ratio is

    G_d(ω) = (1 − e^{−jωT_s})/T_s · Σ_m G(j·ω_m)/(j·ω_m),   ω_m = ω + m·2π/T_s,

with ``G(s) = 1 / (s·(J·s + B)·(τ·s + 1))``. For the double integrator this is the familiar
half-sample delay; τ is what is left. Sines are superimposed on a constant speed so the axis
never reverses: friction is then a constant plus ``B·ω``, and B (as ``B/J``, a phase lead
falling as ``1/ω``) is fitted with τ (a lag rising as ``ω``), the two being separable over
the band. Gravity, cable and cogging vary slowly and go into a per-block polynomial trend.

Which hold: the torque is held over the drive's *control* period, which the recording's rows
need not share. A SYNC-streamed CiA 402 drive reports, once per SYNC, its last control-loop
sample (the position measured at that sample's start, the torque commanded over it): the
pair is the control-rate pair, decimated, so the model is the one above at the control
period (``torque_hold_s``), not at the row spacing (a 1 ms hold instead of 0.25 ms puts a
0.375 ms delay into the model: more than τ). Decimation also aliases the torque's content
near multiples of the row rate onto the band; a drive that *holds* each target over the
SYNC period puts steps there (the velocity loop passes them to the torque) and biases the
phase by as much as τ's own; linear interpolation of the targets (CiA 402 0x60C0 = 0)
leaves a bias of about −0.005 ms (−1.5 % at τ = 0.3 ms; measured on the emulator at 1 kHz
SYNC, 4 kHz loop: it depends on the drive's velocity loop, which the estimator does not
know, so it is not modelled). :func:`torque_hold_s` reads the recording's
metadata and refuses the cases it cannot model.

Averaged torque (``torque_sample = "mean"``, CiA 402 emulator 0x2077): row k carries the
mean of the ``N = T_s/T_c`` control-period torques held over ``[t_k − T_s, t_k]``, the
position is still sampled at ``t_k − T_c``. For a sine ``u_n`` at the control rate the row's
torque is ``u_n · B(ω)`` with the boxcar

    B(ω) = (1/N) Σ_{i<N} e^{−jωiT_c} = (1/N)·(1 − e^{−jωNT_c})/(1 − e^{−jωT_c}),

real-positive times ``e^{−jω(T_s − T_c)/2}`` (a pure delay of ``(T_s − T_c)/2``, 0.375 ms at
1 kHz / 4 kHz, magnitude ``sin(ωT_s/2)/(N·sin(ωT_c/2))``), so the measured ratio is
``G_d(ω)/B(ω)`` with ``G_d`` at the control period, exactly. Relative to the position
sample the averaged torque's centroid sits ``T_c − T_s/2`` later (−0.25 ms: earlier). The
boxcar has zeros at multiples of the row rate, where the point sample aliases the
torque's high-frequency content onto the band: the noise floor goes. The sidebands the
velocity loop makes of a linearly interpolated 1 kHz target (n·1 kHz ± f) are attenuated,
not removed: measured on the emulator τ = +0.4 %, +1.5 %, +0.4 % at 0.21, 0.3, 0.6 ms
(point sample: −2.9 %, −1.7 %, −1.0 %); not modelled. (The +3.5 % once measured at 0.21 ms
was the simulator's exact-hold artefact, since fixed.)

Per frequency the run is cut into blocks of whole periods (all of them: the blocks differ by
at most one period); the phase uncertainty is the scatter of the block phases, each weighed
by its periods (Type A). τ and B/J are a weighted least-squares fit of the
phases; the standard uncertainty of τ is from the fit's covariance, scaled by
``√(χ²/ν)`` when the scatter about the model exceeds the block estimate. The weights are
themselves estimates (``blocks − 1`` degrees of freedom each), so τ's degrees of freedom
are drawn (:mod:`hil.identify.scatter_weights`), not the blocks' pooled count.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from hil.errors import IdentificationError
from hil.identify.estimate import Estimate
from hil.identify.harmonic_fit import fit_harmonics, polynomial_columns
from hil.identify.scatter_weights import coverage_dof, draw_fits
from hil.recording import EVERY_CONTROL_PERIOD

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]
IntArray = NDArray[np.int64]
IMAGES = 200  # aliases summed on each side in the sampled-data response
TREND_ORDER = 1  # constant + linear (the carrier) with each block's sine: higher orders are
# nearly collinear with a one-period sine and inflate the variance (benchmarks/bench_frf.py)


@dataclass(frozen=True, slots=True, kw_only=True)
class TorqueHold:
    """How the drive holds the torque it reports.

    Attributes
    ----------
    hold_s : float
        Period over which the drive holds each torque sample (s): its control period.
    mean_samples : int
        Each reported value is the mean of this many held samples (1: a point sample).

    Raises
    ------
    ValueError
        ``mean_samples`` below 1.
    """

    hold_s: float
    mean_samples: int = 1

    def __post_init__(self) -> None:
        if self.mean_samples < 1:
            raise ValueError(f"mean_samples must be ≥ 1, got {self.mean_samples}")


def conventions_problem(metadata: Mapping[str, str]) -> str | None:
    """Why the model cannot apply to a drive with the conventions ``metadata`` states
    (its object map's ``position_latch`` and ``torque_reports``), or ``None``.

    The model pairs the torque *commanded* over a control period with the position measured
    at that period's start. A drive that reports its measured torque has the current loop's
    lag inside the reported torque already (τ reads about zero), and one that latches the
    position at the SYNC shifts the pair by a control period (τ reads about 80 % short);
    a drive whose map does not say either cannot be told apart from them.
    """
    reports = metadata.get("torque_reports", "demand")
    latch = metadata.get("position_latch", "control_period_before_sync")
    where = f"the object map '{metadata.get('object_map', '?')}'"
    if reports != "demand":
        return (f"{where} says torque_reports = {reports!r}: τ is measured against the torque "
                "the drive commands (\"demand\"), which this drive is not known to report")
    if latch != "control_period_before_sync":
        return (f"{where} says position_latch = {latch!r}: the model needs the position of "
                "the control period's start, latched with that period's torque "
                "(\"control_period_before_sync\")")
    return None


def timing_problem(timing: Mapping[str, str]) -> str | None:
    """Before any motion: why the model cannot apply to the drive whose recordings will
    state ``timing`` (:attr:`hil.drives.base.DriveInfo.timing`), or ``None``."""
    problem = conventions_problem(timing)
    if problem is None and "torque_sample" in timing and "control_period_s" not in timing:
        problem = ("the drive's control period is not known (its object map gives no "
                   "control_period; give control_period_s in the station file): the torque "
                   "hold, and with it τ, cannot be modelled")
    return problem


def torque_hold_s(metadata: Mapping[str, str], *, fs_hz: float) -> TorqueHold:
    """How the drive held the torque a recording reports (module docstring, "Which hold").

    Recordings that do not describe their torque sampling (``torque_sample`` absent: the
    simulator, CSV files) hold it over their own sample period ``1/fs_hz``. A decimated
    record of a faster control loop needs ``control_period_s``, and its command must have
    been interpolated linearly between samples (``command_interpolation``): a held command
    aliases into the band (module docstring). ``torque_sample = "mean"``: the mean over the
    sample period (``torque_mean_period_s``, if stated, must be it) of the torque held per
    control period; ``mean_samples = T_s/T_c``.

    Parameters
    ----------
    metadata : mapping of str to str
        The recording's metadata: ``torque_sample``, ``torque_mean_period_s``,
        ``control_period_s``, ``command_interpolation``.
    fs_hz : float
        The recording's sample rate (Hz).

    Returns
    -------
    TorqueHold
        The period over which the drive held each reported torque sample (s), and how many
        such samples each reported value is the mean of.

    Raises
    ------
    IdentificationError
        The metadata does not say what is needed, or states a sampling that biases τ: a
        sampling other than ``"instantaneous"`` or ``"mean"``, a mean over other than the
        sample period, no ``control_period_s``, a sample period that is not a whole number
        of control periods, or decimation without linear command interpolation.
    """
    sample_s = 1.0 / fs_hz
    problem = conventions_problem(metadata)
    if problem is not None:
        raise IdentificationError(problem)
    if "torque_sample" not in metadata:
        return TorqueHold(hold_s=sample_s)
    sampling = metadata["torque_sample"]
    if sampling not in ("instantaneous", "mean"):
        raise IdentificationError(
            f"torque sampled as {sampling!r}: only an instantaneous control-loop sample or "
            "the mean over the sample period is modelled"
        )
    if sampling == "mean" and "torque_mean_period_s" in metadata:
        mean_s = float(metadata["torque_mean_period_s"])
        if not math.isclose(mean_s, sample_s, rel_tol=1e-6):
            raise IdentificationError(
                f"torque averaged over {mean_s:g} s, the rows are {sample_s:g} s apart: "
                "only a mean over the sample period is modelled"
            )
    try:
        control_s = float(metadata["control_period_s"])
    except (KeyError, ValueError) as exc:
        raise IdentificationError(
            "the recording does not state the drive's control period (control_period_s): "
            "the torque hold, and with it τ, cannot be modelled"
        ) from exc
    ratio = sample_s / control_s
    if ratio < 1 - 1e-6 or abs(ratio - round(ratio)) > 1e-6:
        raise IdentificationError(
            f"sample period {sample_s:g} s is not a whole number of control periods "
            f"({control_s:g} s)"
        )
    interpolation = metadata.get("command_interpolation", "unknown")
    if round(ratio) > 1 and interpolation != "linear":
        raise IdentificationError(
            f"one row per {round(ratio)} control periods with the command interpolated "
            f"{interpolation!r}: a held target's steps alias onto the band and bias τ by as "
            "much as its own phase; use linear target interpolation (CiA 402 0x60C0 = 0) or "
            "record at the control rate (drive recorder)"
        )
    return TorqueHold(hold_s=control_s, mean_samples=round(ratio) if sampling == "mean" else 1)


def acquisition_path(metadata: Mapping[str, str], *, fs_hz: float) -> str:
    """How a recording's torque rows were taken, as a method line names its path:
    :data:`hil.recording.EVERY_CONTROL_PERIOD` (the simulator's, a drive recorder's: the
    method map was measured on it), or ``one row per N control periods, torque SAMPLING``
    (a field bus streaming a faster drive; ``SAMPLING`` ``instantaneous`` or ``mean``).

    Raises
    ------
    IdentificationError
        As :func:`torque_hold_s`: the metadata does not say how the torque was held.
    """
    hold = torque_hold_s(metadata, fs_hz=fs_hz)
    per_row = round(1.0 / (fs_hz * hold.hold_s))
    if per_row <= 1:
        return EVERY_CONTROL_PERIOD
    return f"one row per {per_row} control periods, torque {metadata['torque_sample']}"


def sampled_response(
    frequency_hz: FloatArray | float,
    *,
    fs_hz: float,
    inertia_kg_m2: float,
    viscous_over_inertia_1_s: float,
    time_constant_s: float,
    mean_samples: int = 1,
) -> ComplexArray:
    """Sampled position over held torque, ``G_d(ω)`` above, in rad/N·m (``G_d/B`` with
    ``mean_samples = N > 1``: the torque reported as the mean of the last N held samples).

    Parameters
    ----------
    frequency_hz : float or array
        Excitation frequencies (Hz), below ``fs_hz/2``.
    fs_hz : float
        Sample rate of the drive (Hz): the hold period is ``1/fs_hz``.
    inertia_kg_m2, viscous_over_inertia_1_s, time_constant_s : float
        J (kg·m²), B/J (1/s) and the current-loop time constant τ (s).
    mean_samples : int
        N: each reported torque is the mean of the last N samples held over ``1/fs_hz``.

    Returns
    -------
    ndarray of complex, shape (len(frequency_hz),)
        ``G_d`` (rad/N·m) at each frequency, ``IMAGES`` aliases summed on each side; one
        element for a scalar ``frequency_hz``.
    """
    omega = 2 * math.pi * np.atleast_1d(np.asarray(frequency_hz, dtype=np.float64))
    step_s = 1.0 / fs_hz
    images = 2 * math.pi * fs_hz * np.arange(-IMAGES, IMAGES + 1)
    s = 1j * (omega[:, None] + images[None, :])
    plant = 1.0 / (s * (s + viscous_over_inertia_1_s) * (time_constant_s * s + 1.0))
    total = np.sum(plant / s, axis=1)
    hold = (1.0 - np.exp(-1j * omega * step_s)) / step_s
    response = hold * total / inertia_kg_m2
    if mean_samples > 1:
        response = response / boxcar(omega * step_s, mean_samples)
    return np.asarray(response, dtype=np.complex128)


def boxcar(omega_step: FloatArray, n: int) -> ComplexArray:
    """``B = (1/n)·Σ_{i<n} e^{−j·i·ωT}``: the mean of the last n samples of a sampled sine,
    relative to the newest (delay ``(n−1)T/2``).

    Parameters
    ----------
    omega_step : array
        ``ωT``: angular frequency times the sample period (rad).
    n : int
        Samples averaged.

    Returns
    -------
    ndarray of complex
        ``B`` at each ``ωT`` (at least one-dimensional).
    """
    i = np.arange(n)
    terms = np.exp(-1j * np.multiply.outer(np.atleast_1d(omega_step), i))
    return np.asarray(terms.mean(axis=-1), dtype=np.complex128)


@dataclass(frozen=True, slots=True, kw_only=True)
class FrequencyPoint:
    """One frequency: the measured sampled response and the phase the current loop adds.

    Attributes
    ----------
    frequency_hz : float
        The sine's frequency (Hz).
    response_rad_nm : complex
        Position over reported torque (rad/N·m), H1 over the blocks: ``Σ P·T* / Σ |T|²``.
    lag_phase_rad : float
        Phase of the response relative to the rigid, lag-free sampled model (rad; < 0: lag).
    lag_phase_u_rad : float
        Its standard uncertainty from the scatter of the block phases (rad).
    inertia_kg_m2 : float
        J from the magnitude against the rigid, lag-free model (kg·m²).
    torque_amplitude_nm : float
        Mean torque amplitude over the blocks (N·m).
    blocks : int
        Blocks of whole periods used.
    """

    frequency_hz: float
    response_rad_nm: complex  # H1 over the blocks: Σ P·T* / Σ |T|²
    lag_phase_rad: float  # phase of the response after the rigid, lag-free model (< 0: lag)
    lag_phase_u_rad: float  # standard uncertainty from the block scatter
    inertia_kg_m2: float  # from the magnitude against the rigid, lag-free model
    torque_amplitude_nm: float
    blocks: int


@dataclass(frozen=True, slots=True, kw_only=True)
class CurrentLoopResult:
    """Current-loop time constant τ and B/J fitted to the lag phases.

    Attributes
    ----------
    points : tuple of FrequencyPoint
        The frequencies fitted.
    time_constant : Estimate
        ``current_loop_time_constant_ms``: τ (ms).
    viscous_over_inertia_1_s : float
        The fitted B/J (1/s).
    inertia_kg_m2 : float
        Median J from the magnitudes against the fitted model (kg·m²; informational).
    chi2_per_dof : float
        χ² of the phase fit per degree of freedom (frequencies − 2).
    """

    points: tuple[FrequencyPoint, ...]
    time_constant: Estimate  # current_loop_time_constant_ms
    viscous_over_inertia_1_s: float
    inertia_kg_m2: float  # from the magnitudes against the fitted model (informational)
    chi2_per_dof: float


def block_phasors(
    time_s: FloatArray, signals: Sequence[FloatArray], *, omega: float
) -> list[complex]:
    """Complex amplitude of each signal at ``omega``, fitted with a polynomial trend.

    Parameters
    ----------
    time_s : array
        Sample times of the block (s).
    signals : sequence of array
        Signals sampled at ``time_s``.
    omega : float
        Angular frequency (rad/s).

    Returns
    -------
    list of complex
        ``c − j·s`` per signal, with ``c`` and ``s`` its amplitudes along ``cos(ω·t)`` and
        ``sin(ω·t)`` (a constant and a linear trend fitted alongside).
    """
    centred = time_s - time_s.mean()
    scale = max(float(np.ptp(centred)), 1e-12)
    fit = fit_harmonics(
        omega * time_s,
        np.column_stack(signals),
        trend=polynomial_columns(centred / scale, TREND_ORDER),
    )
    return [complex(fit.cos[0, i], -fit.sin[0, i]) for i in range(len(signals))]


def analyse_frequency(
    time_s: FloatArray,
    position_rad: FloatArray,
    torque_nm: FloatArray,
    *,
    frequency_hz: float,
    fs_hz: float,
    blocks: int,
    hold_s: float | None = None,
    mean_samples: int = 1,
) -> FrequencyPoint:
    """Reduce one sine segment (settled, whole periods) to a :class:`FrequencyPoint`.

    Parameters
    ----------
    time_s, position_rad, torque_nm
        Samples of the segment: time (s), encoder position (rad), reported torque (N·m).
    frequency_hz
        The sine's frequency (Hz).
    fs_hz
        The recording's sample rate (Hz).
    blocks
        Number of blocks of whole periods the segment is cut into (≥ 2; at most one per
        whole period).
    hold_s
        The period over which the drive held each reported torque (s): :func:`torque_hold_s`;
        ``None``: ``1/fs_hz``.
    mean_samples
        Each reported torque is the mean of this many held samples (:func:`torque_hold_s`).

    Returns
    -------
    FrequencyPoint
        The H1 response, the lag phase with its block-scatter uncertainty, J from the
        magnitude, the torque amplitude and the number of blocks.

    Raises
    ------
    IdentificationError
        Fewer than two whole periods, or a block without torque at the frequency.
    """
    hold_fs_hz = fs_hz if hold_s is None else 1.0 / hold_s
    n_mean = mean_samples
    periods = math.floor((time_s[-1] - time_s[0] + 1.0 / fs_hz) * frequency_hz + 1e-6)
    blocks = min(blocks, periods)
    if blocks < 2:
        raise IdentificationError(
            f"{frequency_hz:g} Hz: {periods} whole periods, need at least 2 blocks"
        )
    omega = 2 * math.pi * frequency_hz
    block_periods = np.diff(np.arange(blocks + 1) * periods // blocks)  # all periods, ±1
    edges = np.searchsorted(
        time_s - time_s[0], np.concatenate(([0], np.cumsum(block_periods))) / frequency_hz
        - 0.5 / fs_hz
    )
    p_list, t_list = [], []
    for a, b in itertools.pairwise(edges):
        p_hat, t_hat = block_phasors(time_s[a:b], [position_rad[a:b], torque_nm[a:b]], omega=omega)
        if t_hat == 0:
            raise IdentificationError(f"{frequency_hz:g} Hz: no torque at the frequency")
        p_list.append(p_hat)
        t_list.append(t_hat)
    p_arr, t_arr = np.asarray(p_list), np.asarray(t_list)
    ratio = p_arr / t_arr
    rigid = complex(
        sampled_response(
            frequency_hz,
            fs_hz=hold_fs_hz,
            inertia_kg_m2=1.0,
            viscous_over_inertia_1_s=0.0,
            time_constant_s=0.0,
            mean_samples=n_mean,
        )[0]
    )
    phases = np.angle(ratio / rigid)
    mean = complex(np.sum(p_arr * np.conj(t_arr)) / np.sum(np.abs(t_arr) ** 2))  # H1
    return FrequencyPoint(
        frequency_hz=frequency_hz,
        response_rad_nm=mean,
        lag_phase_rad=float(np.angle(mean / rigid)),
        lag_phase_u_rad=_mean_phase_u_rad(phases, block_periods),
        inertia_kg_m2=abs(rigid) / abs(mean),
        torque_amplitude_nm=float(np.mean(np.abs(t_arr))),
        blocks=blocks,
    )


def _mean_phase_u_rad(phases: FloatArray, block_periods: IntArray) -> float:
    """The standard uncertainty of the phase over all the blocks' periods, from the scatter
    of the block phases (each block's variance is that of one period over its periods)."""
    weights = block_periods / np.sum(block_periods)
    mean = float(np.sum(weights * phases))
    one_period_variance = float(np.sum(block_periods * (phases - mean) ** 2)) / (len(phases) - 1)
    return math.sqrt(one_period_variance / float(np.sum(block_periods)))


def scatter_dof(points: Sequence[FrequencyPoint]) -> FloatArray:
    """Each phase's u is from its blocks' scatter: ``blocks − 1`` degrees of freedom."""
    return np.array([p.blocks - 1 for p in points], dtype=np.float64)


def lag_phase_residual(
    points: Sequence[FrequencyPoint], *, fs_hz: float, mean_samples: int
) -> Callable[[FloatArray], FloatArray]:
    """The weighted phase residual of a current-loop model at ``points``.

    The model's parameters ``x``: τ (ms), B/J (1/s) and, when a third is given, a dead
    time (ms). ``fs_hz`` is the rate of the torque's hold (``1/hold_s`` where it differs).
    """
    freqs = np.array([p.frequency_hz for p in points])
    phases = np.array([p.lag_phase_rad for p in points])
    sigma = np.array([max(p.lag_phase_u_rad, 1e-6) for p in points])
    omega = 2 * math.pi * freqs
    rigid = sampled_response(freqs, fs_hz=fs_hz, inertia_kg_m2=1.0,
                             viscous_over_inertia_1_s=0.0, time_constant_s=0.0,
                             mean_samples=mean_samples)

    def residual(x: FloatArray) -> FloatArray:
        model = sampled_response(freqs, fs_hz=fs_hz, inertia_kg_m2=1.0,
                                 viscous_over_inertia_1_s=float(x[1]),
                                 time_constant_s=float(x[0]) * 1e-3, mean_samples=mean_samples)
        if len(x) > 2:
            model = model * np.exp(-1j * omega * float(x[2]) * 1e-3)
        return np.asarray((np.angle(model / rigid) - phases) / sigma, dtype=np.float64)

    return residual


def fit_current_loop_lag(
    points: Sequence[FrequencyPoint],
    *,
    fs_hz: float,
    hold_s: float | None = None,
    mean_samples: int = 1,
) -> CurrentLoopResult:
    """Weighted least-squares fit of τ and B/J to the lag phases of ``points``.

    Parameters
    ----------
    points : sequence of FrequencyPoint
        At least three frequencies (:func:`analyse_frequency`).
    fs_hz, hold_s, mean_samples
        As for :func:`analyse_frequency` (the same values).

    Returns
    -------
    CurrentLoopResult
        τ as ``current_loop_time_constant_ms`` (Estimate in ms; its uncertainty scaled by
        ``√(χ²/ν)`` when above one; its degrees of freedom those whose Student-t covers
        the drawn fits' error/u, :func:`hil.identify.scatter_weights.coverage_dof`), B/J,
        J from the magnitudes and χ²/ν.

    Raises
    ------
    IdentificationError
        Fewer than three points, the fit did not converge, or τ and B/J are not separable
        over the frequencies.
    """
    n_mean = mean_samples
    fs_hz = fs_hz if hold_s is None else 1.0 / hold_s  # the model only needs the hold
    if len(points) < 3:
        raise IdentificationError(f"{len(points)} frequencies, need at least 3 for τ and B/J")
    residual = lag_phase_residual(points, fs_hz=fs_hz, mean_samples=n_mean)
    freqs = np.array([p.frequency_hz for p in points])
    phases = np.array([p.lag_phase_rad for p in points])
    omega = 2 * math.pi * freqs
    start_ms = max(float(np.median(-phases / omega)) * 1e3, 1e-3)
    fit = least_squares(residual, x0=np.array([start_ms, 1.0]), bounds=([0.0, 0.0], [1e3, 1e4]))
    if not fit.success:
        raise IdentificationError(f"current-loop lag fit did not converge: {fit.message}")
    dof = len(points) - 2
    chi2 = float(np.sum(fit.fun**2))
    chi2_per_dof = chi2 / dof if dof > 0 else math.nan
    jacobian = np.asarray(fit.jac, dtype=np.float64)
    try:
        covariance = np.linalg.inv(jacobian.T @ jacobian)
    except np.linalg.LinAlgError as exc:
        raise IdentificationError("τ and B/J are not separable over these frequencies") from exc
    inflation = max(1.0, chi2_per_dof) if dof > 0 else 1.0
    u_ms = math.sqrt(float(covariance[0, 0]) * inflation)
    drawn = draw_fits(jacobian, scatter_dof(points))
    estimate = Estimate(
        name="current_loop_time_constant_ms",
        value=float(fit.x[0]),
        standard_uncertainty=u_ms,
        unit="ms",
        dof=coverage_dof(drawn, np.array([1.0, 0.0]), inflated=inflation > 1.0),
        cramer_rao_std=math.sqrt(float(covariance[0, 0])),
    )
    fitted = sampled_response(
        freqs,
        fs_hz=fs_hz,
        inertia_kg_m2=1.0,
        viscous_over_inertia_1_s=float(fit.x[1]),
        time_constant_s=float(fit.x[0]) * 1e-3,
        mean_samples=n_mean,
    )
    measured = np.abs([p.response_rad_nm for p in points])
    return CurrentLoopResult(
        points=tuple(points),
        time_constant=estimate,
        viscous_over_inertia_1_s=float(fit.x[1]),
        inertia_kg_m2=float(np.median(np.abs(fitted) / measured)),
        chi2_per_dof=chi2_per_dof,
    )
