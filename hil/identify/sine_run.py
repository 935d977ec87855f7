"""One sinusoidal-velocity run reduced for the J/B/T_c estimators: the analysis window of
whole periods after settling, phase-free kinematics from the encoder, the article's
orthogonal components per period, the reversal band, and the torque's timing.

``hold_samples``: the torque a drive reports at sample k acts on the shaft over the
following control period, so the motion it causes is centred half a control period (plus
the current loop's lag) later; :func:`torque_hold_samples` reads that from the recording.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.signal import butter, sosfiltfilt, sosfreqz

from hil.errors import IdentificationError
from hil.identify.gravity_cable import CableLoop, cable_loop_torque_nm
from hil.identify.harmonic_fit import fit_harmonics, polynomial_columns
from hil.identify.kinematics import phase_free_derivatives
from hil.recording import Recording

FloatArray = NDArray[np.float64]
REVERSAL_BAND = 0.15  # fraction of the velocity amplitude
DERIVATIVE_WINDOW_PERIODS = 0.02  # Savitzky–Golay window, in periods of the sine
PHASE_BINS = 200
HOLD_SAMPLES = 0.5  # the drive holds each reported torque over the following period
#: ``torque_reports`` of a torque measured after the current loop (CiA 402 maps, ODrive)
MEASURED_TORQUE = ("measured", "measured_current")
#: a measured torque's hold, in control periods: the sample trails the torque acting over
#: its period by ``T/(1 − e^{−T/τ}) − T/2 − τ`` for a first-order loop sampled at the
#: period's start, from 1/2 (τ ≪ T) to 0 (τ ≫ T); minus the middle is taken, the range is a
#: rectangular line (:func:`measured_torque_hold_u_s`)
MEASURED_HOLD = -0.25


def orthogonal_components(
    signal: FloatArray, *, time_s: FloatArray, frequency_hz: float
) -> tuple[float, float]:
    """The article's ``c = (2/N)·Σ x·cos`` and ``s = (2/N)·Σ x·sin`` at ``frequency_hz``.

    Computed as least-squares amplitudes of cos, sin and a constant: identical to the sums
    for uniform sampling over whole periods, and still unbiased for irregular timestamps
    or a subset of samples.

    Parameters
    ----------
    signal : array
        The samples.
    time_s : array
        Their times (s).
    frequency_hz : float
        The frequency (Hz).

    Returns
    -------
    c, s : float
        Amplitudes along ``cos(2πft)`` and ``sin(2πft)``, in the unit of ``signal``.
    """
    fit = fit_harmonics(
        2 * math.pi * frequency_hz * time_s, signal, trend=polynomial_columns(time_s, 0)
    )
    return float(fit.cos[0]), float(fit.sin[0])


@dataclass(frozen=True, slots=True, kw_only=True)
class SineRun:
    """One sine run over its analysis window: the article's components and the samples.

    Attributes
    ----------
    frequency_hz : float
        The sine's frequency f (Hz).
    velocity_amplitude_rad_s : float
        V: √2 × the RMS of the analysed velocity (rad/s).
    quadrature_nm, quadrature_u_nm : float
        c, the torque along cos of the measured velocity phase, mean over the periods, and
        its standard uncertainty from their scatter (N·m).
    in_phase_nm, in_phase_u_nm : float
        s, the torque along the measured velocity, likewise (N·m).
    periods : int
        Whole periods analysed.
    noise_rms_nm : float
        RMS of the non-periodic torque: noise, loop jitter (N·m).
    time_s : array
        Sample times from the recording's first sample (s).
    velocity_rad_s, acceleration_rad_s2 : array
        Phase-free ω (rad/s) and α (rad/s²), taken ``hold_samples`` after each row
        (where its torque acts).
    torque_nm : array
        The reported torque (N·m).
    period : array of int
        Period index of each sample, ``0..periods − 1``.
    phase_bin : array of int
        Phase bin of each sample within its period, ``0..PHASE_BINS − 1``.
    moving : array of bool
        Outside the reversal band: ``|ω| > REVERSAL_BAND·V``.
    """

    frequency_hz: float
    velocity_amplitude_rad_s: float
    quadrature_nm: float  # c: torque along cos of the measured velocity phase
    quadrature_u_nm: float
    in_phase_nm: float  # s: torque along the measured velocity
    in_phase_u_nm: float
    periods: int
    noise_rms_nm: float  # non-periodic torque (noise, loop jitter)
    time_s: FloatArray
    velocity_rad_s: FloatArray  # phase-free
    acceleration_rad_s2: FloatArray  # phase-free
    torque_nm: FloatArray
    period: NDArray[np.intp]  # period index of each sample, 0..periods-1
    phase_bin: NDArray[np.intp]  # phase bin of each sample within its period
    moving: NDArray[np.bool_]  # outside the reversal band

    @property
    def inertia_kg_m2(self) -> float:
        """J of this run alone, ``c / (V·2πf)`` (kg·m²)."""
        return self.quadrature_nm / (
            self.velocity_amplitude_rad_s * 2 * math.pi * self.frequency_hz
        )


def synchronous_average(signal: FloatArray, phase_bin: NDArray[np.intp]) -> FloatArray:
    """Each sample replaced by the mean of its phase bin over all periods.

    Parameters
    ----------
    signal : array
        The samples.
    phase_bin : array of int
        Phase bin of each sample, ``0..PHASE_BINS − 1`` (:attr:`SineRun.phase_bin`).

    Returns
    -------
    ndarray
        The periodic part of ``signal``, sample by sample; what is left over is noise and
        non-periodic motion.
    """
    counts = np.bincount(phase_bin, minlength=PHASE_BINS)
    sums = np.bincount(phase_bin, weights=signal, minlength=PHASE_BINS)
    means = np.divide(sums, counts, out=np.zeros(PHASE_BINS), where=counts > 0)
    return means[phase_bin]


def analyse_sine_run(
    recording: Recording,
    *,
    frequency_hz: float,
    settle_periods: int,
    hold_samples: float = HOLD_SAMPLES,
) -> SineRun:
    """Reduce one sinusoidal-velocity run (phase zero at the recording's first sample).

    The first ``settle_periods`` are discarded; every following whole period is used.
    ``hold_samples``: the torque reported at sample k is held by the drive over the next
    period, so the motion it causes is centred that many samples later; the kinematics are
    taken there (0.5 for a zero-order hold; 0 for torque already time-aligned with motion).

    Parameters
    ----------
    recording : Recording
        A velocity-mode sine run.
    frequency_hz : float
        The sine's frequency (Hz).
    settle_periods : int
        Periods discarded at the start.
    hold_samples : float
        See above (samples).

    Returns
    -------
    SineRun
        The article's components ``c`` and ``s`` with their uncertainties, the noise, and
        the analysed samples with their phase-free kinematics, period and phase bin.

    Raises
    ------
    IdentificationError
        Fewer than two whole periods after settling.
    ValueError
        The derivative window is not shorter than the recording
        (:func:`hil.identify.kinematics.phase_free_derivatives`).
    """
    time_s = recording.time_s - recording.time_s[0]
    dt = float(np.median(np.diff(time_s)))
    total = math.floor((time_s[-1] + dt) * frequency_hz + 1e-6)
    periods = total - settle_periods
    if periods < 2:
        raise IdentificationError(
            f"{recording.source}: {total} whole periods at {frequency_hz} Hz, "
            f"need at least {settle_periods + 2} ({settle_periods} settling + 2)"
        )
    velocity, acceleration = phase_free_derivatives(
        recording.position, time_s=time_s, window_s=DERIVATIVE_WINDOW_PERIODS / frequency_hz
    )
    if hold_samples:
        shifted = time_s + hold_samples * dt
        velocity = np.interp(shifted, time_s, velocity)
        acceleration = np.interp(shifted, time_s, acceleration)
    cycles = time_s * frequency_hz
    window = (cycles >= settle_periods - 1e-9) & (cycles < total - 1e-9)
    t, torque = time_s[window], recording.effort[window]
    v, a = velocity[window], acceleration[window]
    period = np.minimum((cycles[window] - settle_periods).astype(np.intp), periods - 1)
    phase_bin = np.minimum(
        (np.mod(cycles[window], 1.0) * PHASE_BINS).astype(np.intp), PHASE_BINS - 1
    )
    amplitude = math.sqrt(2.0) * float(np.sqrt(np.mean(v**2)))

    components = np.array(
        [
            _along_velocity(t[period == k], v[period == k], torque[period == k], frequency_hz)
            for k in range(periods)
        ]
    )
    periodic = synchronous_average(torque, phase_bin)
    noise_rms = float(np.sqrt(np.sum((torque - periodic) ** 2) / max(len(t) - PHASE_BINS, 1)))
    return SineRun(
        frequency_hz=frequency_hz,
        velocity_amplitude_rad_s=amplitude,
        quadrature_nm=float(components[:, 0].mean()),
        quadrature_u_nm=float(components[:, 0].std(ddof=1) / math.sqrt(periods)),
        in_phase_nm=float(components[:, 1].mean()),
        in_phase_u_nm=float(components[:, 1].std(ddof=1) / math.sqrt(periods)),
        periods=periods,
        noise_rms_nm=noise_rms,
        time_s=t,
        velocity_rad_s=v,
        acceleration_rad_s2=a,
        torque_nm=torque,
        period=period,
        phase_bin=phase_bin,
        moving=np.abs(v) > REVERSAL_BAND * amplitude,
    )


def band_noise_rms_nm(run: SineRun, *, harmonics: int) -> float:
    """The level of the non-periodic torque below ``harmonics`` harmonics of the sine, as
    the σ of a white noise: what sets the Cramér–Rao bound of a fit whose regressors hold
    their information there.

    Under a velocity loop the reported torque carries the loop's response to the encoder's
    quantisation, broadband and strongest at high frequency (19 bits, 300 Hz filter: a
    non-periodic RMS of 3.3 mN·m over 2 mN·m of torque noise). That torque moves the shaft
    below one count, so for the fit it is noise, but where the regressors hold their
    information (the sine's first harmonics; ``sgn ω`` keeps 98 % of its power below the
    25th) the spectrum is the torque noise's: the bound of a linear model in coloured noise
    weights each frequency by the spectrum there. In that case the RMS over all
    frequencies states a bound 1.65 × too wide; this band reads 2.1 mN·m, and the bound
    of the coloured noise (quantisation as position noise through the plant's impedance)
    is within 1.4 % of the white bound at the 2 mN·m torque noise.

    Parameters
    ----------
    run : SineRun
        The run.
    harmonics : int
        The band's upper edge in harmonics of ``run.frequency_hz`` (the J/B/T_c fit: 25).

    Returns
    -------
    float
        σ (N·m): the non-periodic torque low-passed (zero phase) at
        ``harmonics``·f, scaled by the filter's noise bandwidth to the whole
        band, and for the share the synchronous average took out (``P/(P − 1)``);
        :attr:`SineRun.noise_rms_nm` when that band reaches Nyquist.
    """
    step_s = float(np.median(np.diff(run.time_s)))
    nyquist_hz = 0.5 / step_s
    cutoff_hz = harmonics * run.frequency_hz
    if cutoff_hz >= 0.5 * nyquist_hz or len(run.torque_nm) < 100:
        return run.noise_rms_nm
    residual = run.torque_nm - synchronous_average(run.torque_nm, run.phase_bin)
    sos = butter(4, cutoff_hz, fs=2 * nyquist_hz, output="sos")
    low = sosfiltfilt(sos, residual)
    # forward and backward: |H|⁴, whose noise bandwidth is 0.898 × the cutoff for order 4
    frequency_hz, response = sosfreqz(sos, worN=8192, fs=2 * nyquist_hz)
    bandwidth_hz = float(np.sum(np.abs(response) ** 4) * (frequency_hz[1] - frequency_hz[0]))
    share = run.periods / (run.periods - 1)
    return math.sqrt(float(np.mean(low**2)) * nyquist_hz / bandwidth_hz * share)


def _along_velocity(
    t: FloatArray, velocity: FloatArray, torque: FloatArray, frequency_hz: float
) -> tuple[float, float]:
    """(c, s): torque components along cos and sin of the period's measured velocity phase."""
    v_cos, v_sin = orthogonal_components(velocity, time_s=t, frequency_hz=frequency_hz)
    phase = math.atan2(v_cos, v_sin)  # v ≈ V·sin(ωt + φ)
    a, b = orthogonal_components(torque, time_s=t, frequency_hz=frequency_hz)
    return a * math.cos(phase) - b * math.sin(phase), b * math.cos(phase) + a * math.sin(phase)


def torque_hold_samples(recording: Recording, *, current_loop_lag_s: float) -> float:
    """How many samples after its position sample the torque of the same row acts on the
    shaft, plus the current loop's lag.

    An instantaneous torque sample is held over the drive's control period (the
    recording's own period unless ``control_period_s`` says otherwise): half of it. A torque
    the drive measured (:func:`measured_torque`) has the current loop's lag inside it (give
    none then); sampled at the period's start, it trails the torque acting over the period
    by 0 (a loop slow against the period) to half a period (a fast one), so its motion is
    centred before the row: a quarter period before is taken (:data:`MEASURED_HOLD`), the
    range is :func:`measured_torque_hold_u_s`. A
    torque averaged over the row period ``T_s`` (``torque_sample = "mean"``) has its
    centroid ``T_c − T_s/2`` after the position sample, which is taken a control period
    ``T_c`` before the row.

    Parameters
    ----------
    recording : Recording
        The run; its metadata says how the torque was sampled.
    current_loop_lag_s : float
        The current loop's lag (s), e.g. its time constant τ.

    Returns
    -------
    float
        The delay in samples of the recording's median step (``hold_samples`` of
        :func:`analyse_sine_run`).
    """
    step_s = float(np.median(np.diff(recording.time_s)))
    control_s = float(recording.metadata.get("control_period_s", step_s))
    if recording.metadata.get("torque_sample") == "mean":
        mean_s = float(recording.metadata.get("torque_mean_period_s", step_s))
        hold_s = control_s - 0.5 * mean_s
    elif measured_torque(recording):
        hold_s = MEASURED_HOLD * control_s
    else:
        hold_s = HOLD_SAMPLES * control_s
    return (hold_s + current_loop_lag_s) / step_s


def measured_torque(recording: Recording) -> bool:
    """Whether the recording's torque is one the drive measured after its current loop
    (``torque_reports`` ``"measured"`` or ``"measured_current"``: K_t times the measured
    current), not the torque it commanded."""
    return recording.metadata.get("torque_reports") in MEASURED_TORQUE


def measured_torque_hold_u_s(recording: Recording) -> float:
    """The standard uncertainty of when a measured torque acts (s): the rectangular range
    around :data:`MEASURED_HOLD`, a quarter of the control period each way; 0 for a torque
    the drive commanded, or an averaged one."""
    if not measured_torque(recording) or recording.metadata.get("torque_sample") == "mean":
        return 0.0
    step_s = float(np.median(np.diff(recording.time_s)))
    control_s = float(recording.metadata.get("control_period_s", step_s))
    return abs(MEASURED_HOLD) * control_s / math.sqrt(3)


def without_cable_loop(recording: Recording, loop: CableLoop | None) -> Recording:
    """The recording with the cable's measured hysteresis torque taken out of the effort.

    Parameters
    ----------
    recording : Recording
        The run.
    loop : CableLoop or None
        The cable's loop (:func:`hil.identify.gravity_cable.cable_loop_torque_nm` along the
        recorded position); ``None``: no correction.

    Returns
    -------
    Recording
        A copy whose ``torque_nm`` column is the effort minus the loop's torque, or
        ``recording`` itself when ``loop`` is ``None``.
    """
    if loop is None:
        return recording
    torque = recording.effort - cable_loop_torque_nm(
        recording.position, half_width_nm=loop.half_width_nm, angle_rad=loop.angle_rad
    )
    return Recording(
        columns={**recording.columns, "torque_nm": torque},
        metadata=recording.metadata,
        source=recording.source,
        warnings=recording.warnings,
    )
