"""cross_coupling: the protocol's library (spec, excitation, analysis); the test and its
declared measurements are in ``protocols/test_cross_coupling.py``.

The torque the azimuth needs while the elevation swings: the inner gimbal's products of
inertia with its elevation axis, ``c(el) = C_level·cos(el) + C_vertical·sin(el)`` (numerics
and the model in :mod:`hil.identify.cross_coupling`). The azimuth passes its travel at a
constant speed each way twice, first with the elevation standing at ``centre_rad``, then
with its drive swinging it ``centre_rad + a·sin(2πft)`` over the same travel: the difference
of the two passes is the coupling's, whatever the azimuth's own position- and speed-bound
torques are.

Skips without a ``[protocols.cross_coupling]`` table (not an azimuth axis) and on a station
that cannot move the elevation along a path while the azimuth runs (``REQUIRES``). Like the
inertia across elevation, the results are in shaft-torque units when the torque-constant
protocol measured the reported torque's gain.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hil.beside import Beside
from hil.calibration import CalibrationRun
from hil.details import RunDetails
from hil.drives.base import Capability, DriveInfo
from hil.identify.cross_coupling import CouplingRun
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.inertia_elevation import GAIN
from hil.suite.needs import Need
from hil.suite.protocol import Position, Protocol
from hil.suite.stop_rule import StopRule
from hil.suite.travel import move_excitation, move_speed_rad_s, speed_ramp

NAME = "cross_coupling"
#: the results this protocol measures, in the certificate's order
MEASUREMENTS = ("coupling_product_level_kg_m2", "coupling_product_vertical_kg_m2")
#: what it takes from earlier protocols: the K_t protocol's gain (shaft-torque units), the
#: azimuth's J (the velocity loop's give under the coupling is taken out with it)
INERTIA = Need(protocol="inertia_friction", result="inertia_kg_m2",
               without="the loop's give taken out with the profile's nominal J")
NEEDS: tuple[Need, ...] = (GAIN, INERTIA)
#: what the station must have beyond the drive contract
REQUIRES: tuple[Capability, ...] = (Capability.ELEVATION_AXIS, Capability.ELEVATION_MOTION)
AZIMUTH_RAMP_S = 0.5  # the azimuth's speed ramps (raised cosine)
SETTLE_S = 0.25  # left out after the swing reaches its amplitude (the loops settle)


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec:
    """The passes: the azimuth's speed and the travel's centre, the elevation's swing."""

    speed_rad_s: float
    azimuth_centre_rad: float
    centre_rad: float  # the elevation's, the swing's middle
    amplitude_rad: float
    frequency_hz: float
    periods: int  # whole swing periods at full amplitude per pass (the fit's)
    ramp_periods: int  # swing periods to grow to the amplitude (and to shrink back)
    fs_hz: float
    move_speed_rad_s: float
    stop: StopRule | None = None  # run again until U is reached (hil.suite.stop_rule)

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        """The spec from the profile's ``[protocols.cross_coupling]`` table and the drive.

        Raises
        ------
        ProfileError
            A missing, mistyped, unknown or out-of-range key.
        """
        settings = profile.settings(NAME)
        spec = cls(
            speed_rad_s=settings.number("speed_rad_s", 0.2),
            azimuth_centre_rad=settings.number("azimuth_centre_rad", 0.0),
            centre_rad=settings.number("centre_rad", 0.0),
            amplitude_rad=settings.number("amplitude_rad", 0.4),
            frequency_hz=settings.number("frequency_hz", 1.0),
            periods=settings.integer("periods", 5),
            ramp_periods=settings.integer("ramp_periods", 1),
            fs_hz=min(profile.sample_rate_hz, info.max_sample_rate_hz),
            move_speed_rad_s=move_speed_rad_s(settings, info),
            stop=StopRule.from_settings(settings),
        )
        for key, value in (("speed_rad_s", spec.speed_rad_s),
                           ("amplitude_rad", spec.amplitude_rad),
                           ("frequency_hz", spec.frequency_hz)):
            if not value > 0:
                raise settings.error(key, f"must be > 0, got {value}")
        if spec.periods < 3 or spec.ramp_periods < 1:
            raise settings.error("periods", "at least 3 periods and 1 ramp period are needed")
        settings.done()
        return spec

    @property
    def pass_s(self) -> float:
        """One pass: the speed ramps, the swing's growth and decay, the steady periods."""
        return (2 * AZIMUTH_RAMP_S + (2 * self.ramp_periods + self.periods)
                / self.frequency_hz)

    @property
    def travel_rad(self) -> float:
        """How far the azimuth turns in one pass."""
        return self.speed_rad_s * (self.pass_s - AZIMUTH_RAMP_S)


def _pass(spec: Spec, *, direction: int, swinging: bool) -> tuple[Excitation, NDArray[np.bool_]]:
    """One pass (``direction`` ±1) and its steady samples."""
    fs = spec.fs_hz
    up = speed_ramp(spec.speed_rad_s, ramp_s=AZIMUTH_RAMP_S, fs_hz=fs, up=True)
    down = speed_ramp(spec.speed_rad_s, ramp_s=AZIMUTH_RAMP_S, fs_hz=fs, up=False)
    cruise = round((2 * spec.ramp_periods + spec.periods) / spec.frequency_hz * fs)
    speed = direction * np.concatenate([up, np.full(cruise, spec.speed_rad_s), down])
    t = np.arange(cruise) / fs
    grow = spec.ramp_periods / spec.frequency_hz
    envelope = np.clip(np.minimum(t, t[-1] - t) / grow, 0.0, 1.0)
    envelope = 0.5 - 0.5 * np.cos(math.pi * envelope)  # raised cosine: no step in θ̈
    swing = spec.amplitude_rad * envelope * np.sin(2 * math.pi * spec.frequency_hz * t)
    path = np.full(speed.shape, spec.centre_rad)
    if swinging:
        path[len(up):len(up) + cruise] += swing
    steady = np.zeros(speed.shape, dtype=bool)
    first = len(up) + round((grow + SETTLE_S) * fs)
    steady[first:first + round(spec.periods / spec.frequency_hz * fs) - round(SETTLE_S * fs)] \
        = True
    way = "forward" if direction > 0 else "backward"
    name = f"{'swinging' if swinging else 'standing'}_{way}"
    return Excitation(name=name, mode=Mode.VELOCITY, command=speed, fs_hz=fs,
                      elevation_path_rad=path,
                      metadata={"elevation_swing": f"{spec.amplitude_rad:g} rad at "
                                f"{spec.frequency_hz:g} Hz" if swinging else "none"}), steady


def steady_samples(spec: Spec, name: str) -> NDArray[np.bool_]:
    """The steady samples of the pass called ``name`` (its excitation's)."""
    direction = 1 if name.endswith("forward") else -1
    return _pass(spec, direction=direction, swinging=name.startswith("swinging"))[1]


def motion(spec: Spec, *, position: Callable[[], float],
           set_elevation: Callable[[float], None] = lambda _: None) -> Iterator[Excitation]:
    """The protocol's one sequence: the elevation to the swing's centre (the station's
    other axis, not this drive's motion), the azimuth to the start of its travel, then the
    standing passes forward and back and the swinging ones over the same travel.

    Yields
    ------
    Excitation
        A position-mode move, then four velocity passes.
    """
    set_elevation(spec.centre_rad)
    start = spec.azimuth_centre_rad - spec.travel_rad / 2
    yield move_excitation("move_to_start", position(), start, fs_hz=spec.fs_hz,
                          speed_rad_s=spec.move_speed_rad_s, hold_s=0.2)
    for swinging in (False, True):
        for direction in (1, -1):
            yield _pass(spec, direction=direction, swinging=swinging)[0]


def coupling_runs(spec: Spec, passes: dict[str, Recording]) -> list[CouplingRun]:
    """Each direction's swinging pass with its standing one, as the numerics take them."""
    runs = []
    for way in ("forward", "backward"):
        swinging, standing = passes[f"swinging_{way}"], passes[f"standing_{way}"]
        runs.append(CouplingRun(
            time_s=swinging.columns["time_s"], torque_nm=swinging.columns["torque_nm"],
            azimuth_rad=swinging.columns["position_rad"],
            elevation_rad=swinging.columns["elevation_rad"],
            baseline_time_s=standing.columns["time_s"],
            baseline_torque_nm=standing.columns["torque_nm"],
            baseline_azimuth_rad=standing.columns["position_rad"],
            steady=steady_samples(spec, f"swinging_{way}")[:len(swinging.columns["time_s"])],
            periods=spec.periods))
    return runs


def azimuth_inertia_kg_m2(calibration: CalibrationRun, profile: UnitProfile) -> float:
    """The azimuth's J for the loop's give: the sine protocol's, else the profile's nominal
    (0 when it declares none: the give then stays in the products, a few per cent)."""
    measured = INERTIA.read(calibration)
    if measured is not None:
        return measured.value
    declared = profile.measurements.get("inertia_kg_m2")
    return 0.0 if declared is None else declared.nominal


def planned_motion(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    """The protocol's excitations as the run will command them, from the profile alone."""
    return motion(Spec.from_profile(profile, info), position=at)


@dataclass(frozen=True, slots=True, kw_only=True)
class CrossCouplingDetails(RunDetails):
    """The certificate's details: the model, the swing, what the fit took besides the
    products (ΔJ and P as the Coriolis term shows them, J), the torque's scale."""

    model: str
    swing: str
    azimuth_speed_rad_s: float
    coriolis_delta_j_kg_m2: float
    coriolis_product_kg_m2: float
    azimuth_inertia_kg_m2: float  # J the loop's give was taken out with
    azimuth_give_rms_nm: float
    residual_rms_nm: float
    samples: int
    torque_scale: str


PROTOCOL = Protocol(name=NAME, measurements=MEASUREMENTS, needs=NEEDS, requires=REQUIRES,
                    planned_motion=planned_motion, details=CrossCouplingDetails,
                    beside=Beside(moves_other=True))  # the elevation swings
