"""Plots of the closed-loop protocols: the velocity loop's Bode plots with its bandwidth and
margins, the step responses, the following error without and with feedforward, the
standstill jitter and torque ripple, the cogging ripple with the table cleared and loaded.

Each takes a :class:`~hil.report.data.ProtocolData` and returns a figure, or ``None`` when
the run kept too little to draw (a protocol that stopped before its analysis).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import reduce

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from hil.closed_loop.step import SETTLING_BAND, smoothed_velocity
from hil.closed_loop.tracking import following_error
from hil.recording import Recording
from hil.report.data import ProtocolData, sample_rate_hz
from hil.report.figures import COLOURS, MEASURED, MODEL, new_figure, thin
from hil.suite.cogging_compensation import CoggingCompensationDetails
from hil.suite.standstill import StandstillDetails
from hil.suite.velocity_loop_frf import VelocityLoopFrfDetails
from hil.suite.velocity_step import VelocityStepDetails

FloatArray = NDArray[np.float64]
MICRO = 1e6
MILLI = 1e3
#: Bins of the cogging ripple map over one period of the table's orders.
MAP_BINS = 90
#: Step-response time axis: this many of the slowest settling times (or the whole level).
STEP_SPAN_SETTLINGS = 1.6
STEP_KINDS = tuple(f"{change}, {sign} rotation" for sign in ("+", "−")
                   for change in ("speeding up", "slowing down"))
#: Shown before each step (s): its starting level, and what the zero-phase smoothing spreads.
STEP_LEAD_S = 0.01


def velocity_loop_frf(data: ProtocolData) -> Figure | None:
    """Bode plots of the measured closed loop ``T`` with the sensitivity ``|S|`` (−3 dB
    bandwidth and peak ``|S|`` marked) and of the loop gain ``L`` (gain and phase margins
    marked at their crossovers)."""
    details = data.details_as(VelocityLoopFrfDetails)
    if details is None:
        return None
    freqs = np.asarray(details.frequencies_hz, dtype=float)
    series = [np.asarray(s, dtype=float) for s in (
        details.closed_loop_db, details.closed_loop_deg, details.sensitivity_db,
        details.loop_gain_db, details.loop_gain_deg)]
    figures = [data.value(f"velocity_{n}") for n in ("bandwidth_hz", "gain_margin_db",
                                                     "phase_margin_deg", "sensitivity_peak_db")]
    if freqs.size < 2 or any(s.size != freqs.size for s in series):
        return None
    bandwidth_hz, gm_db, pm_deg, s_peak_db = figures
    if bandwidth_hz is None or gm_db is None or pm_deg is None or s_peak_db is None:
        return None
    t_db, t_deg, s_db, l_db, l_deg = series
    t_deg, l_deg = _unwrapped_deg(t_deg), _unwrapped_deg(l_deg)
    wgc_hz, wpc_hz = _crossovers_hz(freqs, l_db, l_deg)
    fig = new_figure(columns=2, rows=2, height_in=4.2)
    t_mag, l_mag, t_phase, l_phase = fig.axes
    t_mag.plot(freqs, t_db, "o-", ms=3, color=COLOURS[0], label="|T| = |V/R|")
    t_mag.plot(freqs, s_db, "s-", ms=3, color=COLOURS[1], label="|S| = |E/R|")
    t_mag.axhline(-10 * math.log10(2), color=MEASURED, lw=0.7, ls="--", label="−3 dB")
    t_mag.axhline(s_peak_db, color=COLOURS[1], lw=0.7, ls=":",
                  label=f"peak |S| {s_peak_db:.3g} dB")
    t_mag.set(ylabel="gain (dB)",
              title=f"closed loop and sensitivity: bandwidth {bandwidth_hz:.3g} Hz")
    t_phase.plot(freqs, t_deg, "o-", ms=3, color=COLOURS[0])
    t_phase.set(xlabel="frequency (Hz)", ylabel="phase of T (°)")
    for ax in (t_mag, t_phase):
        ax.axvline(bandwidth_hz, color=MODEL, lw=0.8, ls=":",
                   label="−3 dB bandwidth" if ax is t_mag else None)
    l_mag.plot(freqs, l_db, "o-", ms=3, color=COLOURS[2], label="|L| = |V/E|")
    l_mag.axhline(0.0, color=MEASURED, lw=0.7, ls="--")
    l_mag.set(ylabel="loop gain (dB)",
              title=f"loop gain: gain margin {gm_db:.3g} dB, phase margin {pm_deg:.3g}°")
    l_phase.plot(freqs, l_deg, "o-", ms=3, color=COLOURS[2])
    l_phase.axhline(-180.0, color=MEASURED, lw=0.7, ls="--")
    l_phase.set(xlabel="frequency (Hz)", ylabel="phase of L (°)")
    if wpc_hz is not None:  # the gain margin: |L| below 0 dB where ∠L = −180°
        level = float(np.interp(math.log(wpc_hz), np.log(freqs), l_db))
        l_mag.annotate("", xy=(wpc_hz, level), xytext=(wpc_hz, 0.0),
                       arrowprops={"arrowstyle": "<->", "color": MODEL, "lw": 1.0})
        l_mag.plot([], [], color=MODEL, lw=1.0, label=f"gain margin at {wpc_hz:.3g} Hz")
        l_phase.axvline(wpc_hz, color=MODEL, lw=0.7, ls=":")
    if wgc_hz is not None:  # the phase margin: ∠L above −180° where |L| = 0 dB
        phase = float(np.interp(math.log(wgc_hz), np.log(freqs), l_deg))
        l_phase.annotate("", xy=(wgc_hz, phase), xytext=(wgc_hz, -180.0),
                         arrowprops={"arrowstyle": "<->", "color": MODEL, "lw": 1.0})
        l_phase.plot([], [], color=MODEL, lw=1.0, label=f"phase margin at {wgc_hz:.3g} Hz")
        l_mag.axvline(wgc_hz, color=MODEL, lw=0.7, ls=":")
    for ax in fig.axes:
        ax.set_xscale("log")
    # legends below the axes, off the data: each column's under it
    fig.legend(*t_mag.get_legend_handles_labels(), loc="outside lower left", ncols=3)
    handles, labels = (a + b for a, b in zip(l_mag.get_legend_handles_labels(),
                                             l_phase.get_legend_handles_labels(), strict=True))
    fig.legend(handles, labels, loc="outside lower right", ncols=2)
    return fig


def _unwrapped_deg(phase_deg: FloatArray) -> FloatArray:
    """Phase (°) without the ±180° jumps of its wrapped values, from its first line."""
    return np.asarray(np.degrees(np.unwrap(np.radians(phase_deg))), dtype=np.float64)


def _crossovers_hz(freqs: FloatArray, gain_db: FloatArray, phase_deg: FloatArray
                   ) -> tuple[float | None, float | None]:
    """Gain crossover (first fall of ``|L|`` through 0 dB) and phase crossover (first fall
    of ``∠L`` through −180°), each interpolated over log frequency; ``None`` outside the
    lines."""
    def first_fall(y: FloatArray, level: float) -> float | None:
        below = np.flatnonzero((y[:-1] >= level) & (y[1:] < level))
        if below.size == 0:
            return None
        i = int(below[0])
        x0, x1 = math.log(freqs[i]), math.log(freqs[i + 1])
        return math.exp(x0 + (level - y[i]) * (x1 - x0) / (y[i + 1] - y[i]))

    return first_fall(gain_db, 0.0), first_fall(phase_deg, -180.0)


def velocity_step(data: ProtocolData) -> Figure | None:
    """Every step of the staircases, normalised to its size (``(v − v₀)/Δ``) against the
    time after the step, small and large apart: each step's 10 % and 90 % crossings, the
    2 % settling band, the mean overshoot and settling time."""
    details = data.details_as(VelocityStepDetails)
    runs = [r for r in (data.recording("steps_forward"), data.recording("steps_backward"))
            if r is not None]
    if details is None or not details.steps or not runs:
        return None
    steps, smooth_s = details.steps, details.smooth_s
    smallest = min(abs(s.target_rad_s - s.start_rad_s) for s in steps)
    responses = [s for recording in runs
                 for s in _step_responses(recording, smooth_s, jump_rad_s=0.5 * smallest)]
    if len(responses) != len(steps):
        return None
    fig = new_figure()
    settling_ms = max(s.settling_time_s for s in steps) * MILLI
    for ax, size in zip(fig.axes, ("small", "large"), strict=True):
        mine = [(s, r) for s, r in zip(steps, responses, strict=True) if s.size == size]
        rise, overshoot, settling = (data.value(f"step_{n}_{size}_{u}") for n, u in
                                     (("rise_time", "ms"), ("overshoot", "pct"),
                                      ("settling_time", "ms")))
        progress0, fs0_hz, lead0 = mine[0][1]
        span_ms = min((len(progress0) - lead0) / fs0_hz * MILLI, STEP_SPAN_SETTLINGS * settling_ms)
        ax.axhspan(1 - SETTLING_BAND, 1 + SETTLING_BAND, color=MEASURED, alpha=0.25, lw=0,
                   label="settling band ± 2 %")
        for level in (0.1, 0.9):
            ax.axhline(level, color=MEASURED, lw=0.6, ls=":")
            ax.text(0.4 * span_ms, level + 0.015, f"{level:.0%}", fontsize=6, color=MEASURED)
        for i, (step, (progress, fs_hz, lead)) in enumerate(mine):
            t_ms = (np.arange(len(progress)) - lead) / fs_hz * MILLI
            keep = t_ms <= span_ms
            kind = _step_kind(step.start_rad_s, step.target_rad_s)
            colour = COLOURS[STEP_KINDS.index(kind) % len(COLOURS)]
            ax.plot(t_ms[keep], progress[keep], color=colour, lw=0.9, label=kind)
            crossings = [_first_crossing_ms(progress[lead:], fs_hz, level) for level in (0.1, 0.9)]
            ax.plot(crossings, [0.1, 0.9], "|", color=colour, ms=7, mew=1.2,
                    label="its 10 % and 90 % crossings" if i == 0 else None)
        if overshoot is not None:
            ax.axhline(1 + overshoot / 100, color=MODEL, lw=0.8, ls="--", label="mean overshoot")
        if settling is not None:
            ax.axvline(settling, color=MODEL, lw=0.8, ls="-.", label="mean settling time")
            ax.text(settling + 0.01 * span_ms, 0.45, f"{settling:.3g} ms", rotation=90,
                    fontsize=6, color=MODEL, va="center")
        figures = [f"{name} {value:.3g} {unit}" for name, value, unit in
                   (("rise", rise, "ms"), ("overshoot", overshoot, "%")) if value is not None]
        delta = abs(mine[0][0].target_rad_s - mine[0][0].start_rad_s)
        ax.axvline(0.0, color=MEASURED, lw=0.6)
        ax.set(xlim=(-STEP_LEAD_S * MILLI, span_ms),
               xlabel=f"time after a step of Δ = {delta:.2g} rad/s (ms)",
               ylabel="(v − v₀) / Δ (1)", title=f"{size} steps: " + ", ".join(figures))
    # legends below the axes, off the data
    handles, labels = fig.axes[0].get_legend_handles_labels()
    order = sorted(range(len(labels)), key=lambda i: (labels[i] not in STEP_KINDS,
                                                      STEP_KINDS.index(labels[i])
                                                      if labels[i] in STEP_KINDS else i))
    fig.legend([handles[i] for i in order], [labels[i] for i in order],
               loc="outside lower center", ncols=4)
    return fig


def _step_kind(start_rad_s: float, target_rad_s: float) -> str:
    """``speeding up`` or ``slowing down``, and the direction of rotation."""
    change = "speeding up" if abs(target_rad_s) > abs(start_rad_s) else "slowing down"
    return f"{change}, {'+' if target_rad_s > 0 else '−'} rotation"


def _step_responses(recording: Recording, smooth_s: float, *, jump_rad_s: float
                    ) -> list[tuple[FloatArray, float, int]]:
    """Each step of a staircase recording (where its command jumps by more than
    ``jump_rad_s`` in a sample), as ``(v − v₀)/Δ`` from :data:`STEP_LEAD_S` before the step
    to the next one, with the sample rate (Hz) and the samples before the step."""
    command = recording.velocity_cmd
    if command is None:
        return []
    fs_hz = sample_rate_hz(recording)
    velocity = smoothed_velocity(recording.position, fs_hz=fs_hz, smooth_s=smooth_s)
    # a step is a jump of the command; the ramps move it far less per sample
    starts = np.flatnonzero(np.abs(np.diff(command)) > jump_rad_s) + 1
    if starts.size < 2:
        return []
    hold = int(np.median(np.diff(starts)))
    trim = round(smooth_s * fs_hz)  # the smoothing would see the next step
    lead = min(round(STEP_LEAD_S * fs_hz), int(starts[0]))
    out = []
    for start in starts:
        before, after = float(command[start - 1]), float(command[start])
        segment = velocity[start - lead: start + hold - trim]
        out.append(((segment - before) / (after - before), fs_hz, lead))
    return out


def _first_crossing_ms(progress: FloatArray, fs_hz: float, level: float) -> float:
    """When ``progress`` first reaches ``level`` (ms after the step, linear between samples)."""
    above = np.flatnonzero(progress >= level)
    if above.size == 0:
        return math.nan
    i = int(above[0])
    if i == 0:
        return 0.0
    before, after = float(progress[i - 1]), float(progress[i])
    return (i - 1 + (level - before) / (after - before)) / fs_hz * MILLI


def tracking(data: ProtocolData) -> Figure | None:
    """The following error ``θ − θ*`` over the standard move without and with the friction
    feedforward, and the move's velocity command."""
    runs = [(label, data.recording(name)) for label, name in
            (("without feedforward", "move_no_ff"), ("with feedforward", "move_ff"))]
    rms_off, rms_on = data.value("tracking_rms_error_no_ff_urad"), data.value(
        "tracking_rms_error_urad")
    reduction = data.value("tracking_ff_reduction")
    if any(r is None or r.velocity_cmd is None for _, r in runs) or rms_off is None \
            or rms_on is None:
        return None
    fig = new_figure(columns=1, rows=2, height_in=4.2)
    top, bottom = fig.axes
    grid = top.get_gridspec()
    if grid is not None:  # the command, for orientation, smaller than the error
        grid.set_height_ratios([2.2, 1.0])
    bottom.sharex(top)
    top.tick_params(labelbottom=False)
    command_shown = False
    for (label, recording), colour, rms in zip(runs, (COLOURS[1], COLOURS[0]),
                                               (rms_off, rms_on), strict=True):
        command = None if recording is None else recording.velocity_cmd
        if recording is None or command is None:
            return None
        fs_hz = sample_rate_hz(recording)
        error = following_error(recording.position, command, fs_hz=fs_hz)
        t = np.arange(error.samples) / fs_hz
        top.plot(*thin(t, error.error_rad * MICRO), color=colour, lw=0.9,
                 label=f"{label}: RMS {rms:.4g} µrad")
        if not command_shown:
            bottom.plot(*thin(t, command), color=MEASURED, lw=1.2)
            command_shown = True
    top.axhline(0.0, color=MEASURED, lw=0.6)
    ratio = "" if reduction is None else f": feedforward reduces the RMS × {reduction:.3g}"
    top.set(ylabel="following error θ − θ* (µrad)",
            title=f"tracking the standard move{ratio}")
    bottom.set(xlabel="time in the move (s)", ylabel="command ω* (rad/s)")
    fig.legend(*top.get_legend_handles_labels(), loc="outside lower center", ncols=2)
    return fig


def standstill(data: ProtocolData) -> Figure | None:
    """The held position and the reported torque over each hold's analysed block, about
    the block's straight line (what the RMS is taken of), end to end, with each block's
    ± RMS."""
    hold = data.recording("move_and_hold")
    details = data.details_as(StandstillDetails)
    ripple, jitter = data.value("standstill_torque_ripple_mnm"), data.value(
        "standstill_jitter_urad")
    if hold is None or details is None or ripple is None or jitter is None:
        return None
    windows, torque_rms = details.block_windows, details.block_torque_rms_mnm
    jitter_rms = details.block_position_rms_urad
    if not windows or not len(windows) == len(torque_rms) == len(jitter_rms):
        return None
    fs_hz = sample_rate_hz(hold)
    blocks = len(windows)
    n = int(windows[0][1]) - int(windows[0][0])
    if n < 10 or int(windows[-1][1]) > len(hold):
        return None
    position = _block_detrended(hold.position, windows) * MICRO
    torque = _block_detrended(hold.effort, windows) * MILLI
    t = np.arange(n * blocks) / fs_hz
    lsb_urad = _step_urad(hold.position)
    fig = new_figure()
    left, right = fig.axes
    for ax, values, rms, colour, label in ((left, position, jitter_rms, COLOURS[0], "position"),
                                           (right, torque, torque_rms, COLOURS[2], "torque")):
        style = {"ls": "none", "marker": ".", "ms": 1.2} if ax is left else {"lw": 0.5}
        ax.plot(*thin(t, values), color=colour, **style,  # type: ignore[arg-type]
                label=f"{label} about its block's line")
        edges = np.arange(blocks + 1) * n / fs_hz
        level = np.append(np.asarray(rms, dtype=float), rms[-1])
        for sign in (1.0, -1.0):
            ax.step(edges, sign * level, where="post", color=MODEL, lw=1.1, ls="--",
                    label="± block RMS" if sign > 0 else None)
        for edge in edges[1:-1]:
            ax.axvline(edge, color=MEASURED, lw=0.6, ls=":")
        ax.set_xlabel("time in the analysed blocks, one per hold position (s)")
        top = max(float(np.max(np.abs(values))), float(np.max(rms)))
        ax.set_ylim(-1.15 * top, 1.15 * top)
    step = "" if lsb_urad is None else f" (encoder step {lsb_urad:.3g} µrad)"
    left.set(ylabel="position jitter (µrad)",
             title=f"position jitter: {jitter:.3g} µrad RMS{step}")
    right.set(ylabel="torque ripple (mN·m)", title=f"torque ripple: {ripple:.3g} mN·m RMS")
    # legends below the axes, off the data
    fig.legend(*left.get_legend_handles_labels(), loc="outside lower left", ncols=2,
               markerscale=6)
    fig.legend(*right.get_legend_handles_labels(), loc="outside lower right", ncols=2)
    return fig


def _block_detrended(values: FloatArray, windows: Sequence[tuple[int, int]]) -> FloatArray:
    """Each block (``[start, stop]`` samples) less its mean and straight line, end to end
    (as the standstill analysis takes them)."""
    rows = np.stack([np.asarray(values[int(a):int(b)], dtype=float) for a, b in windows])
    n = rows.shape[1]
    ramp = np.arange(n) - (n - 1) / 2
    rows = rows - rows.mean(axis=1, keepdims=True)
    rows = rows - (rows @ ramp / (ramp @ ramp))[:, None] * ramp[None, :]
    return np.asarray(rows.reshape(-1), dtype=np.float64)


def _step_urad(position_rad: FloatArray) -> float | None:
    """The smallest change of the recorded position (µrad): the encoder's step."""
    changes = np.abs(np.diff(position_rad))
    changes = changes[changes > 1e-12]
    return float(changes.min()) * MICRO if changes.size else None


def cogging_compensation(data: ProtocolData) -> Figure | None:
    """The position ripple against the angle within one period of the table's orders with
    the table cleared and loaded (binned means and the fitted harmonics), and each order's
    ripple amplitude cleared and loaded."""
    details = data.details_as(CoggingCompensationDetails)
    orders = [] if details is None else list(details.orders)
    window = () if details is None else details.analysed_s
    runs = [(label, data.recording(name)) for label, name in
            (("table cleared", "pass_uncompensated"), ("table loaded", "pass_compensated"))]
    cleared, loaded = (data.value(f"cogging_ripple_{n}_urad")
                       for n in ("uncompensated", "compensated"))
    removed = data.value("cogging_compensation_removed_pct")
    if not orders or len(window) != 2 or any(r is None for _, r in runs) or cleared is None \
            or loaded is None:
        return None
    fig = new_figure()
    left, right = fig.axes
    period_rad = 2 * math.pi / reduce(math.gcd, orders)
    width = 0.8 / len(runs)
    for i, ((label, recording), colour) in enumerate(zip(runs, (COLOURS[1], COLOURS[0]),
                                                         strict=True)):
        assert recording is not None
        fs_hz = sample_rate_hz(recording)
        part = slice(round(float(window[0]) * fs_hz), round(float(window[1]) * fs_hz))
        theta = recording.position[part]
        if len(theta) < 4 * (4 + 2 * len(orders)):
            return None
        ripple, amplitudes, coef = _ripple_fit(np.arange(len(theta)) / fs_hz, theta, orders)
        phase = np.mod(theta, period_rad)
        which = np.minimum((phase / period_rad * MAP_BINS).astype(int), MAP_BINS - 1)
        counts = np.bincount(which, minlength=MAP_BINS)
        mean = np.bincount(which, ripple, minlength=MAP_BINS) / np.maximum(counts, 1)
        centres = (np.arange(MAP_BINS) + 0.5) / MAP_BINS * period_rad
        left.plot(np.degrees(centres[counts > 0]), MICRO * mean[counts > 0], ".", ms=2.5,
                  color=colour, label=f"{label}, bin means")
        grid = np.linspace(0.0, period_rad, 300)
        left.plot(np.degrees(grid), MICRO * _harmonics(grid, orders, coef), color=colour,
                  lw=1.2, ls="--", label=f"{label}, fitted orders")
        right.bar(np.arange(len(orders)) + (i - (len(runs) - 1) / 2) * width,
                  MICRO * amplitudes, width=width, color=colour, label=label)
    left.set(xlabel=f"position within {math.degrees(period_rad):.3g}° (°)",
             ylabel="position ripple (µrad)", title="residual cogging in the motion")
    # legends below the axes, off the data (the bars' colours are the map's)
    fig.legend(*left.get_legend_handles_labels(), loc="outside lower center", ncols=4,
               markerscale=3)
    share = "" if removed is None else f": {removed:.3g} % removed"
    right.set_xticks(np.arange(len(orders)), [str(o) for o in orders])
    right.set(xlabel="order (periods per revolution)", ylabel="ripple amplitude (µrad)",
              title=f"largest order {cleared:.3g} → {loaded:.3g} µrad{share}")
    return fig


def _ripple_fit(time_s: FloatArray, position_rad: FloatArray, orders: list[int]
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """As :func:`hil.closed_loop.ripple.position_ripple`'s fit: the position less its cubic
    in time (rad), each order's amplitude (rad) and the harmonics' coefficients."""
    t = (time_s - time_s.mean()) / max(float(np.ptp(time_s)), 1e-12)
    trend = np.column_stack([np.ones_like(t), t, t**2, t**3])
    harmonic = np.column_stack([f(n * position_rad) for n in orders for f in (np.sin, np.cos)])
    coef, *_ = np.linalg.lstsq(np.column_stack([trend, harmonic]), position_rad, rcond=None)
    ripple = position_rad - trend @ coef[:4]
    pairs = coef[4:].reshape(-1, 2)
    return ripple, np.hypot(pairs[:, 0], pairs[:, 1]), coef[4:]


def _harmonics(theta: FloatArray, orders: list[int], coef: FloatArray) -> FloatArray:
    """``Σ aₙ·sin(nθ) + bₙ·cos(nθ)`` (rad)."""
    total = np.zeros_like(theta)
    for n, (a, b) in zip(orders, coef.reshape(-1, 2), strict=True):
        total += a * np.sin(n * theta) + b * np.cos(n * theta)
    return total

