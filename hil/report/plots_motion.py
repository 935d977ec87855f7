"""Plots of the motion protocols: the J/B/T_c sine fit, the Stribeck curve, the gravity and
cable sweep with its hysteresis loop, azimuth inertia across elevation, the cross-coupling
between the axes.

Each takes a :class:`~hil.report.data.ProtocolData` and returns a figure, or ``None`` when
the run kept too little to draw (a protocol that stopped before its analysis).
"""

from __future__ import annotations

import re

import numpy as np
from matplotlib.figure import Figure

from hil.identify.kinematics import phase_free_derivatives, zero_phase_lowpass
from hil.identify.sine_run import analyse_sine_run
from hil.identify.stribeck import stribeck_curve
from hil.report.data import ProtocolData, finite
from hil.report.figures import COLOURS, MEASURED, MODEL, new_figure, thin
from hil.suite.cross_coupling import CrossCouplingDetails
from hil.suite.gravity_cable import GravityCableDetails
from hil.suite.inertia_elevation import InertiaElevationDetails
from hil.suite.inertia_friction import InertiaFrictionDetails
from hil.suite.stribeck import StribeckDetails
from hil.suite.torque_constant import TorqueConstantDetails

SINE_NAME = re.compile(r"sine_(?P<hz>[0-9.]+)hz")


def inertia_friction(data: ProtocolData) -> Figure | None:
    """Measured torque against the fitted ``J·α + B·ω + T_c·sgn ω`` over the last two
    periods of each amplitude, and the friction the fit leaves, ``τ − J·α``, against ω."""
    j, b, tc = (data.value(p) for p in ("inertia_kg_m2", "viscous_nm_s_rad", "coulomb_nm"))
    runs = data.recordings_named("sine_")
    if j is None or b is None or tc is None or not runs:
        return None
    details = data.details_as(InertiaFrictionDetails)
    fig = new_figure()
    left, right = fig.axes
    settle = 2 if details is None else details.settle_periods
    top_speed = 0.0
    for i, (name, recording) in enumerate(runs):
        match = SINE_NAME.match(name)
        frequency_hz = (details.frequency_hz if details is not None
                        else float(match["hz"]) if match else None)
        if frequency_hz is None:
            continue
        run = analyse_sine_run(recording, frequency_hz=frequency_hz, settle_periods=settle,
                               hold_samples=0.0)
        last = run.period >= run.periods - 2
        t = run.time_s[last] - run.time_s[last][0]
        omega, alpha, torque = (x[last] for x in (run.velocity_rad_s, run.acceleration_rad_s2,
                                                   run.torque_nm))
        model = j * alpha + b * omega + tc * np.sign(omega)
        load = float(np.mean(torque - model))  # gravity and cable at the sine's centre
        model = model + load
        top_speed = max(top_speed, float(np.max(np.abs(omega))))
        colour = COLOURS[i % len(COLOURS)]
        amplitude = f"{run.velocity_amplitude_rad_s:.2g} rad/s"
        left.plot(*thin(t, torque), color=colour, alpha=0.45, lw=0.7,
                  label=f"measured, {amplitude}")
        left.plot(*thin(t, model), color=colour, lw=1.4, ls="--", label=f"fit, {amplitude}")
        right.plot(*thin(omega, torque - j * alpha - load), ".", color=colour, ms=1.5,
                   alpha=0.5, label=f"{amplitude}")
    speed = np.linspace(-1.05, 1.05, 401) * top_speed
    right.plot(speed, b * speed + tc * np.sign(speed), color=MODEL, lw=1.4,
               label="B·ω + T_c·sgn ω")
    left.set(xlabel="time in the last two periods (s)", ylabel="torque (N·m)",
             title="J·α + B·ω + T_c·sgn ω + static load against the torque")
    right.set(xlabel="velocity ω (rad/s)", ylabel="τ − J·α − static load (N·m)",
              title="what is left: the friction")
    # legends below the axes, off the data
    fig.legend(*left.get_legend_handles_labels(), loc="outside lower left", ncols=2)
    fig.legend(*right.get_legend_handles_labels(), loc="outside lower right", markerscale=6)
    return fig


def stribeck(data: ProtocolData) -> Figure | None:
    """The staircase's speed points (± 2u; stick-slip speeds marked) and the fitted curve."""
    details = data.details_as(StribeckDetails)
    static, vs = data.value("static_friction_nm"), data.value("stribeck_velocity_rad_s")
    if details is None or not details.points or static is None or vs is None:
        return None
    points, coulomb, viscous = details.points, details.coulomb_nm, details.viscous_nm_s_rad
    fig = new_figure(columns=1)
    (ax,) = fig.axes
    for stick, marker, label in ((False, "o", "speed point ± 2u"),
                                 (True, "x", "stick-slip (left out)")):
        chosen = [(p, p.friction_nm) for p in points
                  if p.stick_slip == stick and p.friction_nm is not None]
        if not chosen:
            continue
        ax.errorbar([p.speed_rad_s for p, _ in chosen], [friction for _, friction in chosen],
                    yerr=[2 * (p.friction_u_nm or 0.0) for p, _ in chosen], fmt=marker,
                    color=MEASURED if stick else COLOURS[0], ms=4, capsize=2, label=label)
    speeds = [p.speed_rad_s for p in points]
    grid = np.geomspace(min(speeds) / 1.5, max(speeds) * 1.5, 300)
    ax.plot(grid, stribeck_curve(grid, coulomb_nm=coulomb, static_nm=static,
                                 stribeck_velocity_rad_s=vs, viscous_nm_s_rad=viscous),
            color=MODEL, lw=1.4, label="T_c + (T_s − T_c)·exp(−(v/v_s)²) + B·v")
    ax.axvline(vs, color=MODEL, lw=0.7, ls=":")
    ax.set_xscale("log")
    ax.set(xlabel="speed v (rad/s)", ylabel="steady friction (N·m)",
           title=f"Stribeck curve: T_s = {static:.4g} N·m, v_s = {vs:.3g} rad/s, "
                 f"T_c = {coulomb:.4g} N·m")
    fig.legend(loc="outside lower center", ncols=3)
    return fig


def gravity_cable(data: ProtocolData) -> Figure | None:
    """The raw two-way sweep (torque against position: the hysteresis loop) with the load
    model ± the loop's half width, and the load per position bin with its fit."""
    details = data.details_as(GravityCableDetails)
    sweep = data.recording("sweep")
    if sweep is None or details is None:
        return None
    # an axis without gravity (azimuth) declares no m·g·e: its load is the cable's alone
    mge, phase = data.value("gravity_mge_nm") or 0.0, data.value("gravity_phase_rad") or 0.0
    stiffness = data.value("cable_stiffness_nm_rad") or 0.0
    offset = finite(details.offset_nm, 0.0)
    half_width = finite(details.loop_half_width_nm, 0.0)

    def load(theta: np.ndarray) -> np.ndarray:
        return mge * np.cos(theta + phase) + stiffness * theta + offset

    fig = new_figure()
    left, right = fig.axes
    position, torque = sweep.position, sweep.effort
    rising = np.gradient(position) >= 0
    for mask, colour, label in ((rising, COLOURS[0], "sweeping up"),
                                (~rising, COLOURS[1], "sweeping down")):
        left.plot(*thin(position[mask], torque[mask]), ".", ms=0.8, color=colour, label=label)
    grid = np.linspace(float(position.min()), float(position.max()), 300)
    for sign in (1.0, -1.0):
        left.plot(grid, load(grid) + sign * half_width, color=MODEL, lw=1.0, ls="--",
                  label="load ± loop half width" if sign > 0 else None)
    low, high = np.percentile(torque, [1, 99])
    margin = 0.3 * (high - low)
    left.set_ylim(low - margin, high + margin)
    left.set(xlabel="position θ (rad)", ylabel="torque (N·m)",
             title="two-way sweep: the hysteresis loop")
    fig.legend(*left.get_legend_handles_labels(), loc="outside lower left", ncols=2,
               markerscale=8)
    bins = np.asarray(details.load_nm_by_elevation_rad, dtype=float)
    if bins.size:
        right.plot(bins[:, 0], bins[:, 1], "o", ms=2.5, color=COLOURS[2],
                   label="half sum of the passes, per bin")
    right.plot(grid, load(grid), color=MODEL, lw=1.4,
               label="m·g·e·cos(θ + φ) + k·θ + c" if mge else "k·θ + c")
    right.set(xlabel="position θ (rad)", ylabel="load torque (N·m)",
              title="load (gravity + cable) and its fit")
    fig.legend(*right.get_legend_handles_labels(), loc="outside lower right")
    return fig


def inertia_elevation(data: ProtocolData) -> Figure | None:
    """J at each elevation (± 2u) and ``J(el) = J_zenith + ΔJ·cos²(el) + P·sin(2el)``, the
    travel's largest and smallest J marked."""
    details = data.details_as(InertiaElevationDetails)
    level, zenith = data.value("azimuth_inertia_level_kg_m2"), data.value(
        "azimuth_inertia_zenith_kg_m2")
    product = data.value("azimuth_inertia_product_kg_m2") or 0.0
    ratio = data.value("azimuth_inertia_ratio")
    if (details is None or not details.per_elevation or level is None or zenith is None
            or ratio is None):
        return None
    per = details.per_elevation
    fig = new_figure(columns=1)
    (ax,) = fig.axes
    ax.errorbar([p.elevation_rad for p in per], [p.inertia_kg_m2 for p in per],
                yerr=[2 * p.standard_uncertainty for p in per], fmt="o", color=COLOURS[0],
                capsize=3, label="J at an elevation ± 2u")
    low, high = details.travel_rad
    grid = np.linspace(low, high, 200)
    ax.plot(grid, zenith + (level - zenith) * np.cos(grid) ** 2 + product * np.sin(2 * grid),
            color=MODEL, label="J_zenith + ΔJ·cos²(el) + P·sin(2el)")
    at = np.array([details.largest_at_elevation_rad, details.smallest_at_elevation_rad])
    if np.all(np.isfinite(at)):
        ax.plot(at, zenith + (level - zenith) * np.cos(at) ** 2 + product * np.sin(2 * at),
                "v", color=COLOURS[1], label="largest, smallest on the travel")
    ax.set(xlabel="elevation (rad)", ylabel="azimuth inertia (kg·m²)",
           title=f"azimuth inertia across elevation: max/min {ratio:.4g}")
    fig.legend(loc="outside lower center", ncols=3)
    return fig


def cross_coupling(data: ProtocolData) -> Figure | None:
    """Per direction: the azimuth's torque with the elevation swinging less the same pass
    standing (band-limited as the fit's), against time, with the fitted coupling and
    Coriolis torque ``d/dt[c(el)·el̇] + J'(el)·el̇·ψ̇``."""
    details = data.details_as(CrossCouplingDetails)
    level = data.value("coupling_product_level_kg_m2")
    vertical = data.value("coupling_product_vertical_kg_m2")
    swinging = dict(data.recordings_named("swinging_"))
    standing = dict(data.recordings_named("standing_"))
    if details is None or level is None or vertical is None or len(swinging) != 2:
        return None
    fig = new_figure()
    for ax, way in zip(fig.axes, ("forward", "backward"), strict=True):
        moving, still = swinging.get(f"swinging_{way}"), standing.get(f"standing_{way}")
        if moving is None or still is None:
            return None
        t, el = moving.columns["time_s"], moving.columns["elevation_rad"]
        fs = 1.0 / float(np.median(np.diff(t)))
        rate, accel = phase_free_derivatives(el, time_s=t, window_s=0.02)
        az_rate, _ = phase_free_derivatives(moving.columns["position_rad"], time_s=t,
                                            window_s=0.1)
        model = (level * (np.cos(el) * accel - np.sin(el) * rate**2)
                 + vertical * (np.sin(el) * accel + np.cos(el) * rate**2)
                 + rate * az_rate * (-details.coriolis_delta_j_kg_m2 * np.sin(2 * el)
                                     + 2 * details.coriolis_product_kg_m2 * np.cos(2 * el)))
        still_torque = np.interp(t - t[0], still.columns["time_s"] - still.columns["time_s"][0],
                                 still.columns["torque_nm"])
        measured = zero_phase_lowpass(moving.columns["torque_nm"] - still_torque, fs_hz=fs,
                                      cutoff_hz=12.0, segments=((0, len(t)),))
        ax.plot(*thin(t - t[0], 1e3 * measured), color=MEASURED, lw=0.8,
                label="swinging − standing (band-limited)")
        ax.plot(*thin(t - t[0], 1e3 * model), color=MODEL, lw=1.0, label="fitted coupling")
        ax.set(xlabel="time in the pass (s)", ylabel="azimuth torque (mN·m)",
               title=f"azimuth {way}, {details.azimuth_speed_rad_s:g} rad/s")
    fig.suptitle(f"elevation swing {details.swing}")
    fig.legend(*fig.axes[0].get_legend_handles_labels(), loc="outside lower center", ncols=2)
    return fig


def torque_constant(data: ProtocolData) -> Figure | None:
    """Shaft torque against current at each locked angle with its line, and what the line
    leaves (the linearity)."""
    details = data.details_as(TorqueConstantDetails)
    sweeps = data.recordings_named("locked_sweep")
    kt = data.value("torque_constant_nm_a")
    if details is None or not details.per_angle or len(sweeps) != len(details.per_angle) \
            or kt is None:
        return None
    per_angle = details.per_angle
    fig = new_figure()
    left, right = fig.axes
    for i, ((_, recording), line) in enumerate(zip(sweeps, per_angle, strict=True)):
        current, shaft = recording.columns["current_a"], recording.columns["load_torque_nm"]
        fitted = line.slope_nm_a * current + line.intercept_nm
        colour = COLOURS[i % len(COLOURS)]
        label = f"{line.angle_rad:+.2f} rad"
        left.plot(*thin(current, shaft), ".", ms=1.2, color=colour, alpha=0.5)
        order = np.argsort(current)
        left.plot(current[order], fitted[order], color=colour, lw=1.0, label=label)
        # per commanded level: mean current and mean deviation from the line (± 2 s.e.)
        level = np.unique(recording.columns["torque_cmd_nm"], return_inverse=True)[1]
        counts = np.bincount(level)
        mean_i = np.bincount(level, current) / counts
        mean_d = np.bincount(level, 1e3 * (shaft - fitted)) / counts
        spread = np.sqrt(np.bincount(level, (1e3 * (shaft - fitted) - mean_d[level]) ** 2)
                         / counts / np.maximum(counts - 1, 1))
        right.errorbar(mean_i + 0.03 * (i - len(per_angle) / 2), mean_d, yerr=2 * spread,
                       fmt="o-", ms=3, lw=0.8, capsize=2, color=colour, label=label)
    left.set(xlabel="current (A)", ylabel="shaft torque (N·m)",
             title=f"locked rotor: K_t = {kt:.6g} N·m/A")
    right.set(xlabel="current (A)", ylabel="level mean − line (mN·m)",
              title="what each angle's line leaves (± 2 s.e.)")
    fig.legend(*left.get_legend_handles_labels(), loc="outside lower left", ncols=5,
               title="locked at")
    return fig
