"""inertia_friction: the protocol's library (spec, excitation, analysis); the test and its
declared measurements are in ``protocols/test_inertia_friction.py``.

J, B, T_c from sinusoidal velocity at two or more amplitudes (the article's experiment).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from hil.calibration import CalibrationRun
from hil.details import RunDetails
from hil.drives.base import Capability, DriveInfo
from hil.identify.estimate import Component, Estimate
from hil.identify.gravity_cable import CableLoop, cable_load_stiffness, load_stiffness
from hil.identify.inertia_friction import (
    HARMONICS,
    InertiaFrictionResult,
    Method,
    identify_inertia_friction,
    inertia_amplitude_spread,
    stiffness_corrected_inertia,
)
from hil.identify.position_torque import PositionTorque
from hil.identify.sine_run import (
    SineRun,
    analyse_sine_run,
    measured_torque_hold_u_s,
    torque_hold_samples,
    without_cable_loop,
)
from hil.identify.two_mass import ShaftModes, driven_acceleration
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.gravity_cable import GravityCableDetails
from hil.suite.needs import Need, declared_rectangular
from hil.suite.protocol import Position, Protocol
from hil.suite.shaft_input import SHAFT, ShaftInput
from hil.suite.stop_rule import StopRule
from hil.suite.travel import move_excitation, move_speed_rad_s

NAME = "inertia_friction"
#: the results this protocol measures, in the certificate's order
MEASUREMENTS = ("inertia_kg_m2", "viscous_nm_s_rad", "coulomb_nm", "inertia_amplitude_spread_pct")
#: what it takes from earlier protocols (:mod:`hil.suite.needs`)
LAG = Need(protocol="current_loop", result="current_loop_time_constant_ms",
           without="the profile's nominal current-loop lag taken out of the sines, its "
           "limits a rectangular budget line (0 s where the profile declares no τ)")
LAG_MEASURED = "current-loop time constant τ taken out (current_loop)"
LAG_DECLARED = ("current-loop time constant τ not measured: the profile's nominal taken out, "
                "its limits (rectangular)")
#: an unresolved loop angle's re-analyses: s₀·scale + u(s₀)·reach, from an abrupt loop to s₀ + 2u
UNRESOLVED_ANGLES = ((0.05, 0.0), (1.0, 0.5), (1.0, 1.0), (1.0, 2.0))
CABLE = Need(protocol="gravity_cable", result="cable_hysteresis_nm",
             without="the cable's hysteresis loop left in T_c")
STIFFNESS = (
    Need(protocol="gravity_cable", result="gravity_mge_nm",
         without="no gravity stiffness taken out of J (the profile declares no gravity)"),
    Need(protocol="gravity_cable", result="gravity_phase_rad",
         without="gravity's stiffness within ±(|m·g·e| + u), its phase unknown: a "
                 "rectangular line of J"),
    Need(protocol="gravity_cable", result="cable_stiffness_nm_rad",
         without="J not corrected for the load's stiffness"),
)
#: what every sine analysis takes; the J/B/T_c protocol also drives a two-mass axis's load
#: through the shaft the resonance protocol measured (:mod:`hil.suite.shaft_input`)
SINE_NEEDS: tuple[Need, ...] = (LAG, CABLE, *STIFFNESS)
NEEDS: tuple[Need, ...] = (*SINE_NEEDS, SHAFT)
#: what the station must have beyond the drive contract
REQUIRES: tuple[Capability, ...] = ()


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec:
    """Velocity sines of one frequency at two or more amplitudes, and how to fit them."""

    frequency_hz: float
    amplitudes_rad_s: tuple[float, ...]
    settle_periods: int
    periods: int
    fs_hz: float
    method: Method = "least_squares"
    harmonics: int = HARMONICS
    centre_rad: float | None = None  # where the sines start (None: where the axis is)
    move_speed_rad_s: float = 1.0
    stop: StopRule | None = None  # run the sines again until U is reached (stop_rule)

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        """The spec from the profile's ``[protocols.inertia_friction]`` table and the drive.

        Parameters
        ----------
        profile : UnitProfile
            The unit's profile.
        info : DriveInfo
            The drive: its limits and its highest sample rate.

        Returns
        -------
        Spec

        Raises
        ------
        ProfileError
            A missing, mistyped or unknown key.
        """
        settings = profile.settings(NAME)
        method: Method = (
            "least_squares"
            if settings.choice("method", ("orthogonal", "least_squares"), "least_squares")
            == "least_squares"
            else "orthogonal"
        )
        middle = (info.limits.travel_min_rad + info.limits.travel_max_rad) / 2
        spec = cls(
            frequency_hz=settings.number("frequency_hz"),
            amplitudes_rad_s=settings.numbers("amplitudes_rad_s"),
            settle_periods=settings.integer("settle_periods", 2),
            periods=settings.integer("periods", 8),
            fs_hz=min(profile.sample_rate_hz, info.max_sample_rate_hz),
            centre_rad=settings.number("centre_rad", middle),
            move_speed_rad_s=move_speed_rad_s(settings, info),
            method=method,
            harmonics=settings.integer("harmonics", HARMONICS),
            stop=StopRule.from_settings(settings),
        )
        settings.done()
        return spec


def move_to_centre(spec: Spec, centre_rad: float, *, position_rad: float) -> Excitation:
    """To the sines' start: by default the middle of the travel (level, for an elevation
    axis: the least gravity gradient).

    Parameters
    ----------
    spec : Spec
        The protocol's spec (rate, move speed).
    centre_rad : float
        Where the sines start.
    position_rad : float
        Where the axis is now.

    Returns
    -------
    Excitation
        A position-mode move and a 0.2 s hold.
    """
    return move_excitation(
        "move_to_centre",
        position_rad,
        centre_rad,
        fs_hz=spec.fs_hz,
        speed_rad_s=spec.move_speed_rad_s,
        hold_s=0.2,
    )


def excitation(spec: Spec) -> list[Excitation]:
    """One velocity sine per amplitude, whole periods, starting and ending at rest.

    Parameters
    ----------
    spec : Spec
        The protocol's spec.

    Returns
    -------
    list of Excitation
        One velocity-mode excitation per ``spec.amplitudes_rad_s``.
    """
    samples = round((spec.settle_periods + spec.periods) * spec.fs_hz / spec.frequency_hz)
    t = np.arange(samples) / spec.fs_hz
    shape = np.sin(2 * math.pi * spec.frequency_hz * t)
    return [
        Excitation(
            name=f"sine_{spec.frequency_hz:g}hz_{amplitude:g}rad_s",
            mode=Mode.VELOCITY,
            command=amplitude * shape,
            fs_hz=spec.fs_hz,
        )
        for amplitude in spec.amplitudes_rad_s
    ]


def motion(spec: Spec, *, position: Callable[[], float]) -> Iterator[Excitation]:
    """The protocol's motion, the one sequence the test runs and the planner sums: the move
    to the sines' centre (when the spec has one; from ``position()``), then
    :func:`excitation`'s sines.

    Parameters
    ----------
    spec : Spec
        The protocol's spec.
    position : callable
        Where the axis is now: the drive's position when run, the plan's when planned.

    Yields
    ------
    Excitation
        At most one position-mode move, then the velocity sines.
    """
    if spec.centre_rad is not None:
        yield move_to_centre(spec, spec.centre_rad, position_rad=position())
    yield from excitation(spec)


def analyse(
    recordings: list[Recording],
    spec: Spec,
    *,
    current_loop_lag_s: float = 0.0,
    cable_loop: CableLoop | None = None,
    position_torque: PositionTorque | None = None,
    shaft: ShaftModes | None = None,
) -> InertiaFrictionResult:
    """J, B, T_c. The reported torque reaches the shaft half a control period (zero-order
    hold) plus the current loop's lag later, which would otherwise leak into B as
    ``c·2πf·τ``; the cable's hysteresis loop, when measured, is taken out first (it acts as
    a stiff spring just after each reversal: −1.5 % on J, +20 % on B on the demo unit).
    A two-mass axis's load is driven through its shaft (the ringing after each friction
    reversal: B −3.7 % on the demo azimuth left rigid).

    Parameters
    ----------
    recordings : list of Recording
        One per amplitude, as :func:`excitation` ordered them.
    spec : Spec
        The protocol's spec.
    current_loop_lag_s : float
        The current loop's time constant, added to the zero-order hold's delay.
    cable_loop : CableLoop or None
        The cable's hysteresis loop to take out, if measured.
    position_torque : PositionTorque or None
        Cogging and K_t ripple to take out, if measured (the K_t ripple modulates the
        inertial torque over the sine's travel: :mod:`hil.identify.position_torque`).
    shaft : ShaftModes or None
        A two-mass axis's shaft: the regression's α becomes the acceleration the motor
        torque drives (:func:`hil.identify.two_mass.driven_acceleration`); ``None``: rigid.

    Returns
    -------
    InertiaFrictionResult
        See :func:`hil.identify.inertia_friction.identify_inertia_friction`.

    Raises
    ------
    IdentificationError
        A run with too few whole periods, fewer than two runs, or amplitudes too close to
        separate B from T_c.
    """
    if position_torque:
        recordings = [position_torque.without(r) for r in recordings]
    runs = [
        analyse_sine_run(
            without_cable_loop(r, cable_loop),
            frequency_hz=spec.frequency_hz,
            settle_periods=spec.settle_periods,
            hold_samples=torque_hold_samples(r, current_loop_lag_s=current_loop_lag_s),
        )
        for r in recordings
    ]
    if shaft is not None:
        runs = [_driving_the_load(run, shaft) for run in runs]
    return identify_inertia_friction(runs, method=spec.method, harmonics=spec.harmonics)


def _driving_the_load(run: SineRun, shaft: ShaftModes) -> SineRun:
    driven = driven_acceleration(run.acceleration_rad_s2, time_s=run.time_s, shaft=shaft)
    return dataclasses.replace(run, acceleration_rad_s2=driven)


def measured_cable_loop(calibration: CalibrationRun) -> CableLoop | None:
    """The cable's hysteresis loop if ``gravity_cable`` ran earlier.

    Parameters
    ----------
    calibration : CalibrationRun
        The calibration in progress (earlier results and details).

    Returns
    -------
    CableLoop or None
        Half-width, its standard uncertainty and the loop's angle; ``None`` when not
        measured.
    """
    h = CABLE.read(calibration)
    sweep = calibration.details.get(CABLE.protocol)
    if (h is None or not isinstance(sweep, GravityCableDetails)
            or sweep.cable_hysteresis_angle_rad is None):
        return None
    angle_u, covariance = sweep.cable_hysteresis_angle_u_rad, sweep.cable_hysteresis_covariance
    return CableLoop(
        half_width_nm=h.value, half_width_u_nm=h.standard_uncertainty,
        angle_rad=sweep.cable_hysteresis_angle_rad,
        angle_u_rad=angle_u if math.isfinite(angle_u) else 0.0,
        covariance=covariance if math.isfinite(covariance) else 0.0,
    )


def sine_estimates(result: InertiaFrictionResult) -> dict[str, Estimate]:
    """The protocol's results by name: J, B, T_c and the spread of J over the amplitudes.

    Parameters
    ----------
    result : InertiaFrictionResult
        An analysis.

    Returns
    -------
    dict of str to Estimate
    """
    found = (result.inertia, result.viscous, result.coulomb, inertia_amplitude_spread(result))
    return {e.name: e for e in found}


def with_earlier_inputs(
    recordings: list[Recording],
    spec: Spec,
    *,
    lag: Estimate | None,
    loop: CableLoop | None,
    position_torque: PositionTorque | None = None,
    lag_line: str = LAG_MEASURED,
    shaft: ShaftInput | None = None,
) -> dict[str, Estimate]:
    """Every result with the uncertainty of what earlier protocols measured and this one
    takes out as named budget lines: the sines re-analysed with the current loop's lag at
    ``τ + u(τ)`` and the cable loop's half-width at ``h + u(h)`` (GUM 5.1.3, numerically).

    Parameters
    ----------
    recordings : list of Recording
        One per amplitude, as :func:`excitation` ordered them.
    spec : Spec
        The protocol's spec.
    lag : Estimate or None
        The current loop's time constant (seconds), if known.
    lag_line : str
        Its budget line's name (:data:`LAG_MEASURED`, or :data:`LAG_DECLARED` for the
        profile's nominal).
    loop : CableLoop or None
        The cable's hysteresis loop, if measured.
    position_torque : PositionTorque or None
        Cogging and K_t ripple, if measured: their amplitudes at ``1 + u`` and their
        phases at ``+u`` rad (``u`` the map's relative uncertainty) give two lines.
    shaft : ShaftInput or None
        A two-mass axis's shaft modes: one line per figure, re-analysed at ``+u``.

    Returns
    -------
    dict of str to Estimate
        :func:`sine_estimates` of the analysis at the measured inputs, each with one
        Type B line per input.
    """
    lag_s = 0.0 if lag is None else lag.value
    modes = None if shaft is None else shaft.modes

    def at(lag_s: float, loop: CableLoop | None,
           angle_map: PositionTorque | None = position_torque,
           shaft_modes: ShaftModes | None = modes) -> dict[str, Estimate]:
        return sine_estimates(analyse(recordings, spec, current_loop_lag_s=lag_s,
                                      cable_loop=loop, position_torque=angle_map,
                                      shaft=shaft_modes))

    base = at(lag_s, loop)
    inputs: list[tuple[str, float, str, dict[str, Estimate]]] = []
    if lag is not None and lag.standard_uncertainty > 0:
        inputs.append((lag_line, lag.standard_uncertainty, "s",
                       at(lag_s + lag.standard_uncertainty, loop)))
    if (hold_u_s := max(measured_torque_hold_u_s(r) for r in recordings)) > 0:
        inputs.append(("when the drive's measured torque acts: 0 to half a control period "
                       "before its sample (rectangular)", hold_u_s, "s",
                       at(lag_s + hold_u_s, loop)))
    if loop is not None and loop.half_width_u_nm > 0:
        wider = dataclasses.replace(loop, half_width_nm=loop.half_width_nm + loop.half_width_u_nm)
        inputs.append(("cable hysteresis loop h taken out (gravity_cable)",
                       loop.half_width_u_nm, "N·m", at(lag_s, wider)))
    if position_torque and (u := position_torque.relative_u()) > 0:
        # re-measured in every run: the source names the protocol that recorded it
        found_on = "(gravity_cable: its sweep, by cogging's analysis)"
        inputs += [
            (f"cogging and K_t ripple taken out: their amplitudes {found_on}", u, "",
             at(lag_s, loop, position_torque.perturbed(scale=1 + u))),
            (f"cogging and K_t ripple taken out: their phases {found_on}", u, "rad",
             at(lag_s, loop, position_torque.perturbed(phase_rad=u))),
        ]
    if shaft is not None:
        inputs += [(source, u, unit, at(lag_s, loop, shaft_modes=moved))
                   for source, u, unit, moved in shaft.lines()]
    lines = {
        name: [Component.from_change(source=source, standard_uncertainty=u, unit=unit,
                                     change=shifted[name].value - estimate.value)
               for source, u, unit, shifted in inputs]
        for name, estimate in base.items()
    }
    if (loop is not None and loop.half_width_u_nm > 0
            and 0 < loop.angle_u_rad < loop.angle_rad):
        _with_loop_angle(lines, base, loop, *(
            at(lag_s, dataclasses.replace(loop, angle_rad=loop.angle_rad + sign
                                          * loop.angle_u_rad)) for sign in (1, -1)))
    elif loop is not None and loop.angle_u_rad >= loop.angle_rad > 0:
        _with_unresolved_loop_angle(lines, base, loop, [
            at(lag_s, dataclasses.replace(loop, angle_rad=loop.angle_rad * scale
                                          + loop.angle_u_rad * reach))
            for scale, reach in UNRESOLVED_ANGLES])
    return {name: estimate.with_components(*lines[name]) for name, estimate in base.items()}


def _with_loop_angle(lines: dict[str, list[Component]], base: dict[str, Estimate],
                     loop: CableLoop, longer: dict[str, Estimate],
                     shorter: dict[str, Estimate]) -> None:
    """h and s₀ come from one fit and err together (an h fitted high, an s₀ short): the
    h line takes s₀'s share that moves with h (its regression on h), and s₀'s remainder,
    independent of h, is a line of its own. The results bend with s₀ (B has a minimum
    near the true loop): central differences for the slope, and the curvature's own line
    (GUM 5.1.2 note, ``½·(∂²f/∂s₀²)²·u⁴``)."""
    u = loop.angle_u_rad
    slope = loop.covariance / loop.half_width_u_nm**2  # E[δs₀ | δh] = slope·δh
    rest_u = math.sqrt(max(u**2 - slope * loop.covariance, 0.0))
    for name, estimate in base.items():
        up, down = longer[name].value - estimate.value, shorter[name].value - estimate.value
        per_angle = (up - down) / (2 * u)
        curvature = (up + down) / u**2
        h_line = next(c for c in lines[name] if c.source.startswith("cable hysteresis loop h"))
        lines[name] = [
            dataclasses.replace(c, source="cable hysteresis loop h, with the s₀ fitted with "
                                          "it, taken out (gravity_cable)",
                                sensitivity=c.sensitivity + per_angle * slope)
            if c is h_line else c
            for c in lines[name]
        ]
        lines[name] += [
            Component(source="cable hysteresis loop's angle s₀ beyond h taken out "
                             "(gravity_cable)",
                      kind="B", standard_uncertainty=rest_u, unit="rad", sensitivity=per_angle),
            Component(source="cable hysteresis loop's angle s₀, second order (gravity_cable)",
                      kind="B", standard_uncertainty=u**2, unit="rad²",
                      sensitivity=curvature / math.sqrt(2)),
        ]


def _with_unresolved_loop_angle(lines: dict[str, list[Component]], base: dict[str, Estimate],
                                loop: CableLoop, shifted: list[dict[str, Estimate]]) -> None:
    """An s₀ whose u reaches s₀ itself (a gravity sweep too coarse for the loop's turn-over:
    an ODrive at 500 Hz read s₀ 0.058 ± 0.17 rad for 0.02) is not resolved, and the results
    move with it far beyond a linear line: they are re-analysed across ``[~0, s₀ + 2u]``
    (:data:`UNRESOLVED_ANGLES`) and the line is a rectangular distribution over the range
    they span (GUM 4.3.7), standard uncertainty range/√12."""
    for name, estimate in base.items():
        values = [estimate.value, *(found[name].value for found in shifted)]
        spread = (max(values) - min(values)) / math.sqrt(12)
        lines[name].append(Component(
            source="cable hysteresis loop's angle s₀ not resolved (u ≥ s₀): the results' "
                   "range over s₀ from an abrupt loop to s₀ + 2u, rectangular (gravity_cable)",
            kind="B", standard_uncertainty=loop.angle_u_rad, unit="rad",
            sensitivity=spread / loop.angle_u_rad))


def measured_load_stiffness(calibration: CalibrationRun, *, position_rad: float) -> Estimate | None:
    """``dL/dθ`` of gravity and cable at ``position_rad`` if ``gravity_cable`` ran earlier.

    Parameters
    ----------
    calibration : CalibrationRun
        The calibration in progress (earlier results).
    position_rad : float
        Where the stiffness is taken (the sines' centre).

    Returns
    -------
    Estimate or None
        The load's stiffness (N·m/rad): gravity's and the cable's where m·g·e, its phase
        and k_cable were measured, the cable's with gravity bounded where the phase was
        not (:func:`hil.identify.gravity_cable.cable_load_stiffness`), ``None`` without
        k_cable.
    """
    mge, phase, cable = (calibration.result(need.result) for need in STIFFNESS)
    if cable is None:
        return None
    if mge is None or phase is None:
        return cable_load_stiffness(cable_stiffness=cable, mge=mge)
    return load_stiffness(mge=mge, phase=phase, cable_stiffness=cable, position_rad=position_rad)


def declared_current_loop_lag(profile: UnitProfile) -> Estimate | None:
    """The profile's nominal current-loop τ in seconds, its limits a rectangular
    distribution (GUM 4.3.7): what the sines take out when the drive's rate does not let
    the current-loop protocol run (leaving 0 s would put ``J·(2πf)²·τ`` into B, 3 % of the
    demo's B, undeclared). ``None`` when the profile declares no such result."""
    declared = declared_rectangular(profile, LAG.result)
    if declared is None:
        return None
    nominal_ms, u_ms = declared
    return Estimate(name=LAG.result, value=nominal_ms / 1000, unit="s",
                    standard_uncertainty=u_ms / 1000)


def measured_current_loop_lag(calibration: CalibrationRun) -> Estimate | None:
    """The current-loop time constant in seconds, if that protocol ran earlier.

    Parameters
    ----------
    calibration : CalibrationRun
        The calibration in progress (earlier results).

    Returns
    -------
    Estimate or None
        τ in seconds (from ``current_loop_time_constant_ms``), or ``None``.
    """
    tau = LAG.read(calibration)
    if tau is None:
        return None
    return dataclasses.replace(tau, value=tau.value / 1000, unit="s", budget=(),
                               standard_uncertainty=tau.standard_uncertainty / 1000)


@dataclass(frozen=True, slots=True, kw_only=True)
class EarlierInputs:
    """What :func:`analyse_in_calibration` took out with earlier protocols' results."""

    centre_rad: float  # the sines' centre
    load_stiffness_nm_rad: float | None  # there (gravity and cable), None: not measured
    cable_loop_removed: CableLoop | None
    current_loop_lag_compensated_s: float
    position_torque_removed: str  # cogging and K_t ripple taken out, or "none"
    shaft_modes: str  # a two-mass axis's shaft the load was driven through, or "rigid"


def analyse_in_calibration(
    recordings: list[Recording], spec: Spec, calibration: CalibrationRun, *,
    position_torque: PositionTorque | None = None,
    shaft: ShaftInput | None = None,
) -> tuple[InertiaFrictionResult, dict[str, Estimate], EarlierInputs]:
    """J, B, T_c and the amplitude spread with what earlier protocols measured taken out:
    the current loop's lag and the cable's hysteresis loop (their uncertainties as budget
    lines, :func:`with_earlier_inputs`) and the load's stiffness at the sines' centre.
    Also returns what was applied, for the certificate's details.

    Parameters
    ----------
    recordings : list of Recording
        One per amplitude, as :func:`excitation` ordered them.
    spec : Spec
        The protocol's spec.
    calibration : CalibrationRun
        The calibration in progress (earlier results).
    position_torque : PositionTorque or None
        Cogging and K_t ripple measured on the gravity sweep
        (:func:`hil.suite.position_torque.position_torque_of_sweep`), taken out too.
    shaft : ShaftInput or None
        A two-mass axis's shaft (:func:`hil.suite.shaft_input.shaft_input`); ``None``: rigid.

    Returns
    -------
    result : InertiaFrictionResult
        The analysis at the measured inputs (its runs and fit, for the details).
    estimates : dict of str to Estimate
        The protocol's results by name, J stiffness-corrected when the load's stiffness
        is known.
    applied : EarlierInputs
        The centre, the load stiffness, the cable loop and the lag taken out.

    Raises
    ------
    IdentificationError
        As for :func:`analyse`.
    """
    lag, lag_line = _lag(calibration)
    lag_s = 0.0 if lag is None else lag.value
    loop = measured_cable_loop(calibration)
    analysed = analyse(recordings, spec, current_loop_lag_s=lag_s, cable_loop=loop,
                       position_torque=position_torque,
                       shaft=None if shaft is None else shaft.modes)
    estimates = with_earlier_inputs(recordings, spec, lag=lag, loop=loop,
                                    position_torque=position_torque, lag_line=lag_line,
                                    shaft=shaft)
    centre_rad = float(np.mean([np.mean(r.position) for r in recordings]))
    estimates["inertia_kg_m2"], stiffness = _stiffness_taken_out(
        estimates["inertia_kg_m2"], spec, calibration, centre_rad=centre_rad)
    return analysed, estimates, EarlierInputs(
        centre_rad=centre_rad,
        load_stiffness_nm_rad=None if stiffness is None else stiffness.value,
        cable_loop_removed=loop, current_loop_lag_compensated_s=lag_s,
        position_torque_removed=_described(position_torque),
        shaft_modes="rigid" if shaft is None else shaft.described(),
    )


def inertia_at_earlier_inputs(
    recordings: list[Recording], spec: Spec, calibration: CalibrationRun, *,
    position_torque: PositionTorque | None = None,
    shaft: ShaftModes | None = None,
) -> Estimate:
    """J with the lag, the cable loop, cogging and K_t ripple and the load's stiffness
    taken out at their measured values (and a two-mass axis's ``shaft``, given), without
    :func:`with_earlier_inputs`' re-analyses (their budget lines): the inertias across
    elevation, one per elevation."""
    lag = _lag(calibration)[0]
    analysed = analyse(recordings, spec, current_loop_lag_s=0.0 if lag is None else lag.value,
                       cable_loop=measured_cable_loop(calibration),
                       position_torque=position_torque, shaft=shaft)
    centre_rad = float(np.mean([np.mean(r.position) for r in recordings]))
    return _stiffness_taken_out(analysed.inertia, spec, calibration, centre_rad=centre_rad)[0]


def _lag(calibration: CalibrationRun) -> tuple[Estimate | None, str]:
    """The current loop's τ the sines take out and its budget line's name."""
    lag = measured_current_loop_lag(calibration)
    if lag is not None:
        return lag, LAG_MEASURED
    return declared_current_loop_lag(calibration.profile), LAG_DECLARED


def _stiffness_taken_out(inertia: Estimate, spec: Spec, calibration: CalibrationRun, *,
                         centre_rad: float) -> tuple[Estimate, Estimate | None]:
    """J corrected for the load's stiffness at the sines' centre, when known, and that
    stiffness (:func:`measured_load_stiffness`)."""
    stiffness = measured_load_stiffness(calibration, position_rad=centre_rad)
    if stiffness is None:
        return inertia, None
    return stiffness_corrected_inertia(inertia, stiffness=stiffness,
                                       frequency_hz=spec.frequency_hz), stiffness


def _described(position_torque: PositionTorque | None) -> str:
    if not position_torque:
        return "none"
    return (f"cogging orders {[h.order for h in position_torque.cogging]}, K_t ripple orders "
            f"{[h.order for h in position_torque.kt_ripple]} (gravity sweep)")


def planned_motion(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    """The protocol's excitations as the run will command them, from the profile alone."""
    return motion(Spec.from_profile(profile, info), position=at)


@dataclass(frozen=True, slots=True, kw_only=True)
class SineComponent:
    """One amplitude's torque at the sine's frequency: cos (inertia) and sin (friction)."""

    velocity_amplitude_rad_s: float
    quadrature_c_nm: float
    in_phase_s_nm: float
    periods: int


@dataclass(frozen=True, slots=True, kw_only=True)
class InertiaFrictionDetails(RunDetails):
    """The certificate's details: the method, what earlier protocols' results were taken
    out (:func:`analyse_in_calibration`), the fit and each amplitude's components."""

    method: str
    frequency_hz: float
    settle_periods: int
    centre_rad: float
    load_stiffness_nm_rad: float | None
    cable_loop_removed: CableLoop | None
    current_loop_lag_compensated_s: float
    position_torque_removed: str  # these five: EarlierInputs
    fit_pct: float
    noise_rms_nm: float
    components: tuple[SineComponent, ...]
    shaft_modes: str = "rigid"  # EarlierInputs' too (certificates before it: rigid)


PROTOCOL = Protocol(name=NAME, measurements=tuple(MEASUREMENTS), needs=NEEDS,
                    requires=REQUIRES, planned_motion=planned_motion,
                    details=InertiaFrictionDetails)
