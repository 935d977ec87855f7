"""What protocols that move over the travel share: the envelope, the start, the move there."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hil.config import ConfigTable
from hil.drives.base import DriveInfo
from hil.errors import IdentificationError, ProfileError
from hil.identify.moves import position_move, travel_shortfall_rad
from hil.motion import POSITIONING, PURPOSE, Excitation, Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.rate import needed_sample_rate_hz


def move_excitation(
    name: str,
    position_rad: float,
    target_rad: float,
    *,
    fs_hz: float,
    speed_rad_s: float,
    hold_s: float,
) -> Excitation:
    """A smooth position-mode move from ``position_rad`` to ``target_rad``, then a hold.

    Parameters
    ----------
    name : str
        The excitation's name (in the recording and the certificate's details).
    position_rad : float
        Where the axis is now.
    target_rad : float
        Where the move ends.
    fs_hz : float
        Command sample rate.
    speed_rad_s : float
        Peak speed of the move.
    hold_s : float
        Time held at ``target_rad`` after the move.

    Returns
    -------
    Excitation
        A :attr:`Mode.POSITION` excitation.
    """
    command = position_move(
        position_rad, target_rad, fs_hz=fs_hz, speed_rad_s=speed_rad_s, hold_s=hold_s
    )
    return Excitation(name=name, mode=Mode.POSITION, fs_hz=fs_hz, command=command,
                      metadata={PURPOSE: POSITIONING})


def runs_from_start(spec: TravelSpec, runs: Iterable[Excitation], *,
                    position: Callable[[], float]) -> Iterator[Excitation]:
    """Each of ``runs`` after a move to ``spec.start_rad`` (0.2 s hold), each move built
    from ``position()`` when it is reached: the drive's position when run, the plan's when
    planned (a velocity run ends away from its start)."""
    for run in runs:
        yield spec.move_to_start(position(), hold_s=0.2)
        yield run


def on_command_grid(
    recording: Recording, excitation: Excitation
) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """Position and torque at the excitation's sample instants ``k/fs``, and how many rows
    the recording had. A streamed drive returns one row per command sample (returned as
    is); a polled one fewer, irregular rows, interpolated in time onto the command grid so
    analyses that index by command sample still line up.

    Parameters
    ----------
    recording : Recording
        What the drive recorded while it ran ``excitation``.
    excitation : Excitation
        The excitation run; its command length and ``fs_hz`` set the grid.

    Returns
    -------
    position_rad : ndarray
        Position at ``k/fs_hz``, one per command sample.
    torque_nm : ndarray
        Reported torque (the recording's effort) at the same instants.
    rows : int
        Rows the recording had (for the certificate's details).

    Raises
    ------
    IdentificationError
        The recording stops short of the excitation.
    """
    position = values_on_command_grid(recording, excitation, recording.position)
    torque = values_on_command_grid(recording, excitation, recording.effort)
    return position, torque, len(recording)


def values_on_command_grid(recording: Recording, excitation: Excitation,
                           values: NDArray[np.float64]) -> NDArray[np.float64]:
    """One of ``recording``'s columns at the excitation's sample instants (see
    :func:`on_command_grid`).

    Raises
    ------
    IdentificationError
        The recording stops short of the excitation.
    """
    samples = len(excitation.command)
    time_s = recording.time_s - recording.time_s[0]
    if len(time_s) == samples:
        return values
    grid = np.arange(samples) / excitation.fs_hz
    if time_s[-1] < grid[-1] - 2.0 / excitation.fs_hz:
        raise IdentificationError(
            f"{recording.source}: recording ends at {time_s[-1]:.3f} s, the excitation "
            f"'{excitation.name}' at {grid[-1]:.3f} s"
        )
    return np.interp(grid, time_s, values)


def speed_ramp(speed_rad_s: float, *, ramp_s: float, fs_hz: float, up: bool) -> NDArray[np.float64]:
    """Raised-cosine velocity ramp from rest to ``speed_rad_s`` (or back down).

    Parameters
    ----------
    speed_rad_s : float
        Speed at the top of the ramp.
    ramp_s : float
        Duration of the ramp (at least one sample).
    fs_hz : float
        Command sample rate.
    up : bool
        From rest up to ``speed_rad_s`` if True, else from ``speed_rad_s`` down to rest.

    Returns
    -------
    ndarray
        ``round(ramp_s·fs_hz)`` velocity samples (rad/s), ending exactly at the target.
    """
    n = max(round(ramp_s * fs_hz), 1)
    x = (np.arange(n) + 1) / n if up else 1 - (np.arange(n) + 1) / n
    return speed_rad_s * 0.5 * (1 - np.cos(math.pi * x))


MOVE_SPEED_FRACTION = 0.8  # of the unit's velocity limit, for repositioning moves


def move_speed_rad_s(settings: ConfigTable, info: DriveInfo) -> float:
    """Peak speed of repositioning moves: the profile's ``move_speed_rad_s``, by default half
    the unit's velocity limit (moves are not measured; they only cost machine time).

    Parameters
    ----------
    settings : ConfigTable
        The protocol's ``[protocols.NAME]`` table.
    info : DriveInfo
        The drive; ``info.limits.velocity_rad_s`` sets the default.

    Returns
    -------
    float
        Peak speed of repositioning moves (rad/s).

    Raises
    ------
    ProfileError
        ``move_speed_rad_s`` is not a finite number.
    """
    return settings.number("move_speed_rad_s", MOVE_SPEED_FRACTION * info.limits.velocity_rad_s)


@dataclass(frozen=True, slots=True, kw_only=True)
class TravelSpec:
    """Base of a protocol Spec that plans motion inside the unit's travel limits."""

    fs_hz: float
    travel_min_rad: float
    travel_max_rad: float
    margin_rad: float  # kept clear of each travel limit
    move_speed_rad_s: float  # peak speed of repositioning moves

    @staticmethod
    def envelope(
        settings: ConfigTable, profile: UnitProfile, info: DriveInfo
    ) -> dict[str, float]:
        """The TravelSpec fields: rate and limits from profile and drive, margins from the
        settings (``margin_rad`` 0.1 by default, ``move_speed_rad_s`` see
        :func:`move_speed_rad_s`).

        Parameters
        ----------
        settings : ConfigTable
            The protocol's ``[protocols.NAME]`` table.
        profile : UnitProfile
            The unit's profile; its ``sample_rate_hz`` caps ``fs_hz``.
        info : DriveInfo
            The drive: its travel limits and its ``max_sample_rate_hz``.

        Returns
        -------
        dict of str to float
            Keyword arguments for the TravelSpec fields of a subclass's constructor.

        Raises
        ------
        ProfileError
            ``margin_rad`` or ``move_speed_rad_s`` is not a finite number.
        """
        return {
            "fs_hz": min(profile.sample_rate_hz, info.max_sample_rate_hz),
            "travel_min_rad": info.limits.travel_min_rad,
            "travel_max_rad": info.limits.travel_max_rad,
            "margin_rad": settings.number("margin_rad", 0.1),
            "move_speed_rad_s": move_speed_rad_s(settings, info),
        }

    @property
    def start_rad(self) -> float:
        """Where the passes start: the lower travel limit plus the margin."""
        return self.travel_min_rad + self.margin_rad

    @property
    def excitation_start_rad(self) -> float:
        """Where the excitation's command begins (the repositioning move's end):
        :attr:`start_rad` unless a protocol runs in before its passes."""
        return self.start_rad

    def require_travel(self, needed_rad: float, *, protocol: str, source: str) -> None:
        """Refuse a profile whose one-way excitation needs more travel than the limits leave.

        Parameters
        ----------
        needed_rad : float
            Travel the excitation covers in one direction.
        protocol : str
            The protocol's name, for the error.
        source : str
            The profile's path, for the error.

        Raises
        ------
        ProfileError
            ``needed_rad`` exceeds the travel between the limits less both margins.
        """
        shortfall = travel_shortfall_rad(
            needed_rad=needed_rad,
            travel_min_rad=self.travel_min_rad,
            travel_max_rad=self.travel_max_rad,
            margin_rad=self.margin_rad,
        )
        if shortfall > 0:
            raise ProfileError(
                f"[protocols.{protocol}] needs {shortfall:.3g} rad more travel than the "
                "limits leave",
                source=source,
            )

    def move_to_start(self, position_rad: float, *, hold_s: float) -> Excitation:
        """The repositioning move from ``position_rad`` to :attr:`excitation_start_rad`,
        then a hold of ``hold_s`` (see :func:`move_excitation`)."""
        return move_excitation(
            "move_to_start",
            position_rad,
            self.excitation_start_rad,
            fs_hz=self.fs_hz,
            speed_rad_s=self.move_speed_rad_s,
            hold_s=hold_s,
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class SteppedSineSpec(TravelSpec):
    """Base of a Spec whose excitation is velocity sines at several frequencies on top of a
    constant-speed carrier (the axis never reverses): ramp up, one segment of whole periods
    per frequency, ramp down. Subclasses say how long a segment is and its amplitude."""

    frequencies_hz: tuple[float, ...]
    speed_rad_s: float  # the carrier
    settle_s: float  # discarded at the start of each frequency
    ramp_s: float
    blocks: int

    def segment_samples(self, frequency_hz: float) -> int:
        """Settling plus analysed samples at ``frequency_hz`` (whole periods)."""
        raise NotImplementedError

    def amplitude(self, frequency_hz: float) -> float:
        """Velocity amplitude of the sine at ``frequency_hz`` (rad/s)."""
        raise NotImplementedError

    @property
    def needed_sample_rate_hz(self) -> float:
        """The phase at the highest excitation frequency needs ≥ 4 samples per period."""
        return needed_sample_rate_hz(max(self.frequencies_hz))

    def require_carrier_travel(self, *, protocol: str, source: str) -> None:
        """Refuse a profile whose carrier runs past the travel limits.

        Parameters
        ----------
        protocol : str
            The protocol's name, for the error.
        source : str
            The profile's path, for the error.

        Raises
        ------
        ProfileError
            The ramp and every segment at the carrier speed need more travel than the
            limits leave.
        """
        samples = sum(self.segment_samples(f) for f in self.frequencies_hz)
        self.require_travel(
            self.speed_rad_s * (self.ramp_s + samples / self.fs_hz),
            protocol=protocol,
            source=source,
        )

    def carrier_command(self) -> NDArray[np.float64]:
        """The velocity command: ramp up, the sine segments, ramp down.

        Returns
        -------
        ndarray
            Velocity samples (rad/s) at ``fs_hz``: the ramp to the carrier, then per
            frequency ``segment_samples(f)`` samples of carrier + ``amplitude(f)·sin(2πft)``,
            then the ramp back to rest.
        """
        segments = []
        for f in self.frequencies_hz:
            t = np.arange(self.segment_samples(f)) / self.fs_hz
            segments.append(self.speed_rad_s + self.amplitude(f) * np.sin(2 * math.pi * f * t))
        ramp = {
            up: speed_ramp(self.speed_rad_s, ramp_s=self.ramp_s, fs_hz=self.fs_hz, up=up)
            for up in (True, False)
        }
        return np.concatenate([ramp[True], *segments, ramp[False]])
