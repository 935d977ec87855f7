"""Plots of the frequency and order protocols: the current loop's phase against frequency,
the resonance Bode plot with the two-mass fit, the cogging spectrum and map.

Each takes a :class:`~hil.report.data.ProtocolData` and returns a figure, or ``None`` when
the run kept too little to draw.
"""

from __future__ import annotations

import math
from functools import reduce

import numpy as np
from matplotlib.figure import Figure

from hil.identify.current_loop import sampled_response
from hil.identify.orders import MAX_ORDER, Segment, periodogram
from hil.identify.resonance import TwoMassModel, two_mass_response
from hil.report.data import ProtocolData, finite, sample_rate_hz
from hil.report.figures import COLOURS, MEASURED, MODEL, new_figure
from hil.suite.cogging import CoggingDetails
from hil.suite.current_loop import CurrentLoopDetails
from hil.suite.resonance import ResonanceDetails

#: Fraction of each cogging pass left out at its start (the speed settling).
PASS_SETTLE = 0.1
#: Order of the smooth trend (friction, gravity, cable) removed against position.
TREND_ORDER = 6
MAP_BINS = 120


def current_loop(data: ProtocolData) -> Figure | None:
    """The lag phase at each frequency (± 2u) and the sampled-data model with the fitted τ."""
    details = data.details_as(CurrentLoopDetails)
    tau_ms = data.value("current_loop_time_constant_ms")
    sines = data.recording("sines")
    if details is None or not details.points or tau_ms is None or sines is None:
        return None
    points, hold = details.points, details.torque_hold
    mean_samples = hold.mean_samples
    fs_hz = 1.0 / hold.hold_s if hold.hold_s else sample_rate_hz(sines)
    b_over_j = finite(details.viscous_over_inertia_1_s, 0.0)
    freqs = np.array([p.frequency_hz for p in points])
    grid = np.linspace(0.8 * freqs.min(), min(1.1 * freqs.max(), 0.45 * fs_hz), 300)

    def phase_deg(tau_s: float) -> np.ndarray:
        model = sampled_response(grid, fs_hz=fs_hz, inertia_kg_m2=1.0,
                                 viscous_over_inertia_1_s=b_over_j, time_constant_s=tau_s,
                                 mean_samples=mean_samples)
        rigid = sampled_response(grid, fs_hz=fs_hz, inertia_kg_m2=1.0,
                                 viscous_over_inertia_1_s=0.0, time_constant_s=0.0,
                                 mean_samples=mean_samples)
        return np.degrees(np.angle(model / rigid))

    fig = new_figure(columns=1)
    (ax,) = fig.axes
    ax.errorbar(freqs, np.degrees([p.lag_phase_rad for p in points]),
                yerr=np.degrees([2 * p.lag_phase_u_rad for p in points]), fmt="o",
                color=COLOURS[0], ms=4, capsize=2, label="measured lag phase ± 2u")
    ax.plot(grid, phase_deg(tau_ms * 1e-3), color=MODEL, lw=1.4,
            label=f"sampled-data model, τ = {tau_ms:.4g} ms")
    ax.plot(grid, phase_deg(0.0), color=MEASURED, lw=0.8, ls=":", label="no current-loop lag")
    ax.set(xlabel="frequency (Hz)", ylabel="phase after the rigid model (°)",
           title="current loop: phase of the motion against the reported torque")
    fig.legend(loc="outside lower center", ncols=3)  # legends below the axes, off the data
    return fig


def resonance(data: ProtocolData) -> Figure | None:
    """Bode plot of the measured FRF (± 2u) and the fitted two-mass model."""
    details = data.details_as(ResonanceDetails)
    f_r, f_a = data.value("resonance_frequency_hz"), data.value("antiresonance_frequency_hz")
    zeta_r = data.value("resonance_damping_ratio")
    pieces = data.recordings_named("multisine")  # one run, or the first of its pieces
    sine = pieces[0][1] if pieces else data.recording("stepped_sine")
    if (details is None or not details.frf or not math.isfinite(details.inertia_total_kg_m2)
            or sine is None or f_r is None or f_a is None or zeta_r is None):
        return None
    frf = details.frf
    fs_hz = sample_rate_hz(sine)
    model = TwoMassModel(
        inertia_kg_m2=details.inertia_total_kg_m2, antiresonance_hz=f_a,
        antiresonance_damping=finite(details.antiresonance_damping_ratio, 0.0),
        resonance_hz=f_r, resonance_damping=zeta_r,
        viscous_over_inertia_1_s=finite(details.viscous_over_inertia_1_s, 0.0),
        time_constant_s=finite(details.current_loop_time_constant_s, 0.0),
    )
    freqs = np.array([p.frequency_hz for p in frf])
    magnitude = np.array([p.magnitude_rad_nm for p in frf])
    relative_u = np.array([p.relative_u for p in frf])
    grid = np.geomspace(freqs.min(), freqs.max(), 500)
    fitted = two_mass_response(model, grid, fs_hz=fs_hz)
    fig = new_figure(columns=1, rows=2, height_in=4.2)
    top, bottom = fig.axes
    top.errorbar(freqs, magnitude, yerr=2 * relative_u * magnitude, fmt="o", ms=3,
                 color=COLOURS[0], capsize=2, label="measured FRF ± 2u")
    top.plot(grid, np.abs(fitted), color=MODEL, lw=1.3, label="two-mass fit")
    top.set(xscale="log", yscale="log", ylabel="|position / torque| (rad/N·m)",
            title=f"resonance: f_r = {f_r:.4g} Hz, f_a = {f_a:.4g} Hz, ζ_r = {zeta_r:.3g}")
    phase = np.degrees(np.unwrap([p.phase_rad for p in frf]))
    model_phase = np.degrees(np.unwrap(np.angle(fitted)))
    # same branch as the data: shift the model by whole turns to its first measured point
    model_phase += 360.0 * np.round((phase[0] - np.interp(freqs[0], grid, model_phase)) / 360)
    bottom.plot(freqs, phase, "o", ms=3, color=COLOURS[0], label="measured")
    bottom.plot(grid, model_phase, color=MODEL, lw=1.3, label="two-mass fit")
    bottom.set(xscale="log", xlabel="frequency (Hz)", ylabel="phase (°)")
    for ax in (top, bottom):
        for f in (f_r, f_a):
            ax.axvline(f, color=MEASURED, lw=0.7, ls=":")
    fig.legend(*bottom.get_legend_handles_labels(), loc="outside lower center", ncols=2)
    return fig


def cogging(data: ProtocolData) -> Figure | None:
    """The order spectrum of the detrended torque of both passes, orders found marked, and
    the map: the residual against the position within one period of the orders found, with
    the compensation table's cogging + K_t ripple at each pass's torque level."""
    details = data.details_as(CoggingDetails)
    passes = data.recording("passes")
    if details is None or passes is None or not details.orders:
        return None
    orders = list(details.orders)
    position, torque = passes.position, passes.effort
    # one pass up, one down, of equal length (the gravity sweep's have a run-in and a
    # reference before them, a probe after)
    half = details.pass_samples or len(position) // 2
    first = details.pass_first_sample
    segments, levels = [], []
    for start in (first, first + half):
        index = np.arange(start + int(PASS_SETTLE * half), start + half)
        if len(index) < 100:
            return None
        theta, tau = position[index], torque[index]
        centre, scale = float(theta.mean()), float(np.ptp(theta)) / 2 or 1.0
        trend = np.polynomial.polynomial.polyfit((theta - centre) / scale, tau, TREND_ORDER)
        residual = tau - np.polynomial.polynomial.polyval((theta - centre) / scale, trend)
        segments.append(Segment(residual=residual, position_rad=theta))
        levels.append(float(tau.mean()))
    top = min(MAX_ORDER, max(2 * max(orders) + 10, 60))
    spectrum = periodogram(segments, orders=(1, top))
    n_total = sum(len(s.residual) for s in segments)
    amplitude = np.sqrt(2 * np.maximum(spectrum.power, 0.0) / n_total)
    fig = new_figure()
    left, right = fig.axes
    left.vlines(spectrum.orders, 0, amplitude * 1e3, color=COLOURS[0], lw=1.0)
    found = np.isin(spectrum.orders, orders)
    left.plot(spectrum.orders[found], amplitude[found] * 1e3, "v", color=MODEL, ms=5,
              label="orders found: " + ", ".join(str(o) for o in orders))
    left.set(xlabel="order (periods per revolution)", ylabel="amplitude (mN·m)",
             title="torque spectrum against angle (both passes)")
    fig.legend(*left.get_legend_handles_labels(), loc="outside lower left")
    period_rad = 2 * math.pi / reduce(math.gcd, orders)
    grid = np.linspace(0.0, period_rad, 300)
    levels_detail = details.torque_levels_nm or levels
    for i, (segment, colour) in enumerate(zip(segments, COLOURS, strict=False)):
        phase = np.mod(segment.position_rad, period_rad)
        which = np.minimum((phase / period_rad * MAP_BINS).astype(int), MAP_BINS - 1)
        counts = np.bincount(which, minlength=MAP_BINS)
        mean = np.bincount(which, segment.residual, minlength=MAP_BINS) / np.maximum(counts, 1)
        centres = (np.arange(MAP_BINS) + 0.5) / MAP_BINS * period_rad
        label = "up" if i == 0 else "down"
        right.plot(np.degrees(centres[counts > 0]), 1e3 * mean[counts > 0], ".", ms=2.5,
                   color=colour, label=f"measured, pass {label}")
        model = _table_torque(details, grid, level_nm=float(levels_detail[i]))
        right.plot(np.degrees(grid), 1e3 * model, color=colour, lw=1.2, ls="--",
                   label=f"table, pass {label}")
    right.set(xlabel=f"position within {math.degrees(period_rad):.3g}° (°)",
              ylabel="torque ripple (mN·m)", title="cogging and K_t ripple map")
    fig.legend(*right.get_legend_handles_labels(), loc="outside lower right", ncols=2,
               markerscale=3)
    return fig


def _table_torque(details: CoggingDetails, theta: np.ndarray, *, level_nm: float
                  ) -> np.ndarray:
    """Σ cogging A·sin(nθ + φ) + level·Σ ripple a·sin(nθ + ψ), from the compensation table."""
    total = np.zeros_like(theta)
    for c in details.cogging:
        total += c.amplitude_nm * np.sin(c.order * theta + c.phase_rad)
    for r in details.kt_ripple:
        total += level_nm * r.amplitude * np.sin(r.order * theta + r.phase_rad)
    return total

