"""Acquisition over Modbus: the feedback block, the polled run and its recording.

Sample ``k`` of a run: a setpoint is written at ``k/fs`` and the feedback block read half a
period later (away from the loop's response to the new setpoint). A drive that interpolates
its setpoint (``setpoint_interpolation_time``) is sent the command ``lead`` periods ahead
(``setpoint_lead_periods``) and ramps to it over them (each write restarting the ramp: a
first-order approach to the command, no delay at low frequency), so a host that is late by
less than the lead leaves no hold in it; a drive that steps is sent command sample ``k``. Timing:
with a ``timestamp`` register (the drive's free-running clock, latched with the feedback
and read in the same request) ``time_s`` is that clock, unwrapped; otherwise the host's
monotonic clock at the middle of the read, which carries the link's jitter. It uses the
drive only through its :class:`ModbusLink` and a :class:`Feedback` reader.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hil.drives.base import DriveInfo, MotionEnvelope
from hil.drives.modbus.link import ModbusLink
from hil.drives.modbus.regmap import (
    FEEDBACK,
    SETPOINT_INTERPOLATION,
    TIMESTAMP,
    TORQUE_MEAN,
    TORQUE_MEAN_WINDOW,
    TORQUE_OFFSET,
    RegisterMap,
)
from hil.drives.station import ModbusStation
from hil.errors import (
    DriveCommunicationError,
    DriveError,
    DriveFaultError,
    DriveStateError,
    ProfileError,
)
from hil.motion import COMMAND_COLUMN, Excitation
from hil.recording import Recording

log = logging.getLogger(__name__)

MIN_RATE_FRACTION = 0.7  # of the requested sample rate a run must achieve
MAX_HELD_FRACTION = 0.01  # of a run the drive's setpoint may hold (a late master)
WATCHDOG_FAULT = 0x8130  # CiA-style life guard / heartbeat error: the drive lost its master


class Feedback:
    """The drive's feedback block (status, position, velocity, torque, current, and the
    registers latched with them), read in one request per block of the map.

    Parameters
    ----------
    link : ModbusLink
        The drive's link (and register map).
    torque_sample : str
        ``"mean"``: the latched ``torque_mean`` (and its window) are read with the block.

    Raises
    ------
    ProfileError
        Latched registers that cannot be read in one request with the feedback.
    """

    def __init__(self, link: ModbusLink, torque_sample: str) -> None:
        self.link = link
        self.torque_sample = torque_sample
        registers = link.map.registers
        self.has_timestamp = TIMESTAMP in registers
        latched = tuple(
            name
            for name in (TORQUE_MEAN, TORQUE_MEAN_WINDOW)
            if torque_sample == "mean" and name in registers
        ) + ((TIMESTAMP,) if self.has_timestamp else ())
        self.names = FEEDBACK + latched
        self.blocks = link.map.blocks(self.names)
        if latched and len(self.blocks) > 1:
            names = ", ".join(f"'{name}'" for name in latched)
            raise ProfileError(
                f"register{'s' if len(latched) > 1 else ''} {names} must be read in one "
                f"request with the feedback ({', '.join(FEEDBACK)}); they span "
                f"{len(self.blocks)} reads of at most {link.map.max_registers_per_read} "
                "registers",
                source=link.map.source,
            )

    def read(self) -> tuple[float, dict[str, float]]:
        """One poll of the feedback block: (host time at the middle of the read, values)."""
        t0 = time.monotonic()
        words = self.link.read_words(self.blocks)
        t1 = time.monotonic()
        return (t0 + t1) / 2, self.link.decode(words, self.names)

    def bit(self, values: dict[str, float], name: str) -> bool:
        """A status-word bit of ``values`` by its name in the map."""
        return bool(int(values["status_word"]) >> self.link.map.status_bits[name] & 1)


@dataclass(slots=True)
class PolledRun:
    """What one run collected so far: ``(host time, command, feedback values)`` rows, the
    longest pause between two feedback reads, and how long the setpoint held because a
    write came later than the drive's ramp lasted."""

    rows: list[tuple[float, float, dict[str, float]]] = field(default_factory=list)
    longest_pause_s: float = 0.0
    setpoint_held_s: float = 0.0  # time the drive's ramp had ended before the next write


def poll(excitation: Excitation, run: PolledRun, feedback: Feedback,
         envelope: MotionEnvelope | None = None,
         keepalive: Callable[[], None] = lambda: None) -> None:
    """Write the setpoint each sample period (see the module's docstring) and read the
    feedback half a period later, appending ``(host time, command sample due, values)`` rows
    to ``run`` (kept when this raises). ``keepalive`` runs after each row, in the time left
    to the next sample (a gimbal's held axes: their watchdog, their state).

    Raises
    ------
    DriveFaultError
        The drive reports a fault (a communication-watchdog trip names the longest pause).
    DriveStateError
        The drive disabled itself during the run.
    DriveCommunicationError
        A request failed.
    LimitViolationError
        A row's position or velocity left ``envelope`` (the motion monitor; the caller
        quick-stops the drive).
    """
    command = np.asarray(excitation.command, dtype=np.float64)
    offset = excitation.torque_offset_nm
    name = f"{excitation.mode.value}_cmd"
    fs, n = excitation.fs_hz, len(command)
    lead = feedback.link.station.setpoint_lead_periods
    ahead = SETPOINT_INTERPOLATION in feedback.link.map.registers
    samples = np.arange(n, dtype=np.float64)
    last_index = -1
    t0 = time.monotonic()
    written = t0
    run.longest_pause_s = run.setpoint_held_s = 0.0
    previous = t0
    while True:
        index = int((time.monotonic() - t0) * fs)
        if index >= n:
            if offset is not None:
                feedback.link.write_value(TORQUE_OFFSET, 0.0)
            return
        if ahead:
            now = time.monotonic()
            run.setpoint_held_s += max(0.0, now - written - lead / fs)
            written = now
            due = (now - t0) * fs + lead
            feedback.link.write_value(name, float(np.interp(due, samples, command)))
        elif index != last_index:
            feedback.link.write_value(name, float(command[index]))
        if index != last_index:
            if offset is not None:
                feedback.link.write_value(TORQUE_OFFSET, float(offset[index]))
            last_index = index
        # read half a period after the setpoint changed: a drive that steps to it
        # answers with a torque transient whose start would be sampled every time
        delay = t0 + (index + 0.5) / fs - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        stamp, values = feedback.read()
        run.longest_pause_s = max(run.longest_pause_s, stamp - previous)
        previous = stamp
        run.rows.append((stamp - t0, float(command[index]), values))
        violation = None if envelope is None else envelope.violation(
            position_rad=values["position"], velocity_rad_s=values["velocity"],
            time_s=stamp - t0, excitation=excitation.name)
        if violation is not None:
            raise violation
        if feedback.bit(values, "fault"):
            code = int(values["fault_code"])
            why = ""
            if code == WATCHDOG_FAULT:
                why = (
                    f": communication watchdog, the drive saw no request for its watchdog "
                    f"time (station watchdog_s = {feedback.link.station.watchdog_s:g} s); longest "
                    f"pause between our polls this run {run.longest_pause_s:.3f} s "
                    "(host overloaded or stalled?)"
                )
            raise DriveFaultError(
                f"{feedback.link.where}: drive fault at t = {stamp - t0:.3f} s of "
                f"'{excitation.name}'{why}",
                code=code,
            )
        if not feedback.bit(values, "enabled"):
            raise DriveStateError(
                f"{feedback.link.where}: drive disabled itself during '{excitation.name}'"
            )
        keepalive()
        next_due = t0 + (index + 1) / fs
        delay = next_due - time.monotonic()
        if delay > 0:
            time.sleep(delay)


def rate_shortfall(excitation: Excitation, run: PolledRun, link: ModbusLink) -> DriveError | None:
    """The run achieved too few samples for its timing to mean what the protocol
    planned (the connection-time rate is a snapshot; the machine's load may have risen)."""
    achieved = len(run.rows) / max(excitation.duration_s, 1e-9)
    if achieved >= MIN_RATE_FRACTION * excitation.fs_hz:
        return None
    return DriveCommunicationError(
        f"{link.where}: '{excitation.name}' polled at {achieved:.0f} Hz of the "
        f"{excitation.fs_hz:g} Hz requested (< {MIN_RATE_FRACTION:.0%}; longest pause "
        f"{run.longest_pause_s:.3f} s): the host could not keep up, the recording is "
        f"not the planned excitation; lower max_poll_rate_hz in {link.station.source} "
        f"or unload the machine"
    )


def setpoint_holds(
    excitation: Excitation, run: PolledRun, station: ModbusStation, where: str
) -> DriveError | None:
    """The master fell behind the setpoint lead so often that the drive's setpoint held
    for more than ``MAX_HELD_FRACTION`` of the run: a jerk within rows the polled samples
    cannot resolve (J read up to 5 % low), so the recording is not the planned excitation.
    A positioning move (:attr:`Excitation.positioning`) is not refused: it only arrives a
    little later, and no protocol analyses its rows (a short move was refused for one 40 ms
    stall of the host: 10 ms held of 0.5 s)."""
    if run.setpoint_held_s <= MAX_HELD_FRACTION * excitation.duration_s:
        return None
    if excitation.positioning:
        log.warning("%s: '%s': the setpoint held for %.0f ms (host behind the setpoint lead); "
                    "a positioning move, not refused", where, excitation.name,
                    1000 * run.setpoint_held_s)
        return None
    lead = station.setpoint_lead_periods
    # a lead that bridges the longest pause seen would have left no hold
    bridging = max(lead + 1, math.ceil(round(run.longest_pause_s * excitation.fs_hz, 6)) + 1)
    return DriveCommunicationError(
        f"{where}: '{excitation.name}': the host fell behind the setpoint lead "
        f"({lead} period{'s' if lead > 1 else ''}) and the drive's setpoint held for "
        f"{1000 * run.setpoint_held_s:.0f} ms of {excitation.duration_s:g} s (longest pause "
        f"{run.longest_pause_s:.3f} s): the recording is not the planned excitation; raise "
        f"setpoint_lead_periods in {station.source} (to {bridging} for pauses like this one) "
        f"or unload the machine"
    )


def set_interpolation(link: ModbusLink, period_s: float) -> None:
    """Let the drive ramp to each new setpoint over ``period_s`` (if it can)."""
    if SETPOINT_INTERPOLATION not in link.map.registers:
        return
    register = link.map[SETPOINT_INTERPOLATION]
    if round(period_s / register.scale) >= register.modulus:
        raise DriveStateError(
            f"{link.where}: sample period {period_s:g} s exceeds the range of "
            f"'{SETPOINT_INTERPOLATION}' ({(register.modulus - 1) * register.scale:g} s)"
        )
    link.write_value(SETPOINT_INTERPOLATION, period_s)


def to_recording(
    excitation: Excitation, run: PolledRun, feedback: Feedback, info: DriveInfo
) -> Recording:
    """The rows of a polled run as a :class:`Recording`, timed by the drive's clock when the
    map has one (rows read twice within one drive cycle dropped), with metadata stating
    how samples were timed and what the torque column means."""
    rows = run.rows
    host_s = np.asarray([r[0] for r in rows], dtype=np.float64)
    duplicates = 0
    if feedback.has_timestamp and rows:
        time_s = drive_time(feedback.link.map, host_s, [r[2][TIMESTAMP] for r in rows])
        fresh = np.concatenate([[True], np.diff(time_s) > 0])
        duplicates = int(np.sum(~fresh))  # read twice within one drive cycle
        rows = [r for r, keep in zip(rows, fresh, strict=True) if keep]
        time_s = time_s[fresh]
        acquisition = (
            f"polled; time_s = the drive's clock (register '{TIMESTAMP}', latched with "
            "the feedback)"
        )
    else:
        time_s = host_s
        acquisition = "polled; time_s = host clock at mid-read (irregular, link jitter)"
    if SETPOINT_INTERPOLATION in feedback.link.map.registers:
        lead = feedback.link.station.setpoint_lead_periods
        acquisition += (
            f"; setpoint interpolated by the drive over {lead / excitation.fs_hz:g} s to the "
            f"command {lead} sample period{'s' if lead > 1 else ''} ahead"
        )
    else:
        acquisition += "; setpoint stepped at each write"
    mean = feedback.torque_sample == "mean"
    if mean:
        acquisition += (
            f"; torque = the drive's mean since the previous row (register '{TORQUE_MEAN}')"
        )

    def column(key: str) -> np.ndarray:
        return np.asarray([r[2].get(key, np.nan) for r in rows], dtype=np.float64)

    columns = {
        "time_s": time_s,
        "position_rad": column("position"),
        "velocity_rad_s": column("velocity"),
        "torque_nm": column(TORQUE_MEAN if mean else "torque"),
        COMMAND_COLUMN[excitation.mode]: np.asarray([r[1] for r in rows], dtype=np.float64),
    }
    if "current" in feedback.link.map.registers:
        columns["current_a"] = column("current")
    timing: dict[str, str] = {}
    if mean:
        # row k's torque: the mean over the control periods after row k-1's latched
        # sample up to row k's (unless something else read the register between)
        if TORQUE_MEAN_WINDOW in feedback.link.map.registers:
            window = column(TORQUE_MEAN_WINDOW)
            columns["torque_mean_window_s"] = window
        else:
            window = np.diff(time_s)
        period = float(np.median(window)) if window.size else 1.0 / excitation.fs_hz
        timing["torque_mean_period_s"] = f"{period:g}"
    if feedback.has_timestamp and rows:
        timing["drive_clock_at_start_s"] = f"{rows[0][2][TIMESTAMP]:.6f}"
    metadata = {
        **run_identity(feedback.link, info, excitation),
        "acquisition": acquisition,
        "poll_rate_hz": f"{len(rows) / max(excitation.duration_s, 1e-9):.1f}",
        "requested_rate_hz": f"{excitation.fs_hz:g}",
        "longest_gap_s": f"{float(np.max(np.diff(time_s), initial=0.0)):.4f}",
        "duplicate_reads_dropped": str(duplicates),
        "setpoint_held_s": f"{run.setpoint_held_s:.4f}",
        # row k: the drive's state latched at one control period (position measured at
        # its start, torque commanded over it, or with "mean" the mean of the torque
        # commanded per control period over the row's window ending with that period),
        # as the CANopen backend states it
        "torque_sample": feedback.torque_sample,
        **timing,
        "command_interpolation": (
            "linear" if SETPOINT_INTERPOLATION in feedback.link.map.registers else "hold"
        ),
        **(
            {"control_period_s": f"{feedback.link.map.control_period_s:g}"}
            if feedback.link.map.control_period_s is not None
            else {}
        ),
        **excitation.metadata,
    }
    return Recording(columns=columns, metadata=metadata, source=f"modbus:{excitation.name}")


def run_identity(link: ModbusLink, info: DriveInfo, excitation: Excitation) -> dict[str, str]:
    """The metadata naming the drive and the run, whichever way its rows were acquired."""
    return {
        "drive": link.where,
        "unit_id": str(link.station.unit_id),
        **info.identity(),
        "excitation": excitation.name,
        "control_mode": excitation.mode.value,
    }


def drive_time(
    register_map: RegisterMap, host_s: np.ndarray, clock_s: list[float]
) -> np.ndarray:
    """The drive's wrapping clock unwrapped (each step's wrap count chosen to match the
    host's elapsed time), offset to start at the first sample's host time."""
    register = register_map[TIMESTAMP]
    wrap_s = register.modulus * register.scale
    clock = np.asarray(clock_s, dtype=np.float64)
    step = np.diff(clock)
    wraps = np.round((np.diff(host_s) - step) / wrap_s)
    elapsed = np.concatenate([[0.0], np.cumsum(step + wraps * wrap_s)])
    return np.asarray(host_s[0] + elapsed, dtype=np.float64)
