"""Acquisition over CANSimple: the streamed run and its recording.

CANSimple has no SYNC and no PDO mapping: the ODrive sends its feedback (Get_Encoder_Estimates,
Get_Iq, Get_Torques) every feedback period ``T`` on its own clock, and the host answers each
set with one setpoint. Period ``c`` of a run starts with the feedback set latched at its
start; row ``k`` of the recording is the set of period ``k·m`` (``m`` feedback periods per
sample period, 1 at the full rate), paired with command sample ``k``. ``time_s = k / fs``
is counted from the drive's periods (their frames' time stamps in realtime; the host's
steps in lockstep), so a lost set leaves a gap (``lost_samples``), never an invented row.

**Where the setpoint goes.** The ODrive holds a passthrough setpoint until the next one: a
staircase. A setpoint sent right after each feedback set would put every row at the end of
a stair, where the velocity loop's torque has decayed from the step (its sawtooth,
``−K_v·a·T/2``, in quadrature with the motion: J read 8 % low over the emulator at
500 Hz). The host therefore sends each setpoint half a period after the set (realtime: it
waits ``T/2``; the lockstep emulator takes it at the middle of its period), with the
command's value at the *next* period's start (linear between samples): each stair is then
centred on its own sample time, no delay, and each row sits where the sawtooth crosses its
mean.

In realtime the host must answer each set before the next one comes: a set that found
the next one already waiting had its command sent late (``late_commands``); more than
:data:`MAX_LATE_FRACTION` of them make the run a :class:`DriveCommunicationError`, as a
Modbus run whose setpoint held too long is.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from hil.drives.base import DriveInfo, MotionEnvelope
from hil.drives.odrive.link import Feedback
from hil.drives.odrive.protocol import AxisState, error_names, rad
from hil.drives.odrive.state_machine import OdriveStateMachine, setpoint
from hil.errors import DriveCommunicationError, DriveError, DriveStateError
from hil.motion import COMMAND_COLUMN, Excitation
from hil.recording import Recording

MAX_LATE_FRACTION = 0.05  # of a realtime run's rows whose command went out a period late

TORQUE_SOURCE_TEXT = {
    "estimate": "Get_Torques Torque_Estimate (firmware 0.6: K_t·Iq measured, in the ODrive)",
    "target": "Get_Torques Torque_Target (the torque the ODrive's controller commands)",
    "kt_iq": "torque_constant_nm_a × Get_Iq Iq_Measured (computed by the host)",
}
TORQUE_REPORTS = {"estimate": "measured_current", "target": "demand",
                  "kt_iq": "measured_current"}


@dataclass(slots=True)
class StreamedRun:
    """What one run collected so far: ``(row index, command, feedback)`` rows, the rows
    lost, and (realtime) the rows whose command went out late."""

    rows: list[tuple[int, float, Feedback]] = field(default_factory=list)
    lost_samples: int = 0
    late_commands: int = 0


def decimation(excitation: Excitation, feedback_period_s: float) -> int:
    """Feedback periods per sample period of ``excitation``.

    Raises
    ------
    DriveStateError
        The sample period is not a whole number of feedback periods.
    """
    ratio = 1.0 / (excitation.fs_hz * feedback_period_s)
    if round(ratio) < 1 or abs(ratio - round(ratio)) > 1e-6:
        raise DriveStateError(
            f"excitation '{excitation.name}' is sampled at {excitation.fs_hz:g} Hz; this "
            f"ODrive sends its feedback every {feedback_period_s * 1e3:g} ms: the sample rate "
            f"must be {1 / feedback_period_s:g} Hz divided by a whole number")
    return round(ratio)


def stream(excitation: Excitation, states: OdriveStateMachine, run: StreamedRun,
           envelope: MotionEnvelope) -> None:
    """Run ``excitation`` (module docstring), appending rows to ``run`` (kept on error).

    Raises
    ------
    DriveFaultError
        The ODrive reported an axis error (named).
    DriveStateError
        The axis left closed loop without an error.
    DriveCommunicationError
        Feedback stopped, the heartbeat stopped, or more rows were lost than the station's
        ``lost_sample_fraction`` allows.
    LimitViolationError
        A row left ``envelope`` (the caller quick-stops the axis).
    """
    link, station = states.link, states.station
    period_s = station.feedback_period_s
    m = decimation(excitation, period_s)
    command = np.asarray(excitation.command, dtype=np.float64)
    offset = excitation.torque_offset_nm
    n = len(command)
    samples = np.arange(n, dtype=np.float64)

    def frame(c: int) -> tuple[int, bytes]:
        """The setpoint sent in period ``c``: the command at period ``c + 1``'s start."""
        at = (c + 1) / m
        value = float(np.interp(at, samples, command))
        ff = 0.0 if offset is None else float(np.interp(at, samples, offset))
        return setpoint(excitation.mode, value, ff)

    allowed = math.floor(station.lost_sample_fraction * n)
    total = n * m
    if not link.lockstep:
        link.drain()
    first = states.tick()
    received = time.monotonic()
    stamp = first.stamp_s
    feedback: Feedback | None = first
    c = 0
    while True:
        if feedback is not None and c % m == 0:
            k = c // m
            run.rows.append((k, float(command[k]), feedback))
            _check_row(excitation, states, feedback, k / excitation.fs_hz, envelope)
        if not link.lockstep:  # half a period after the set (module docstring)
            delay = received + period_s / 2 - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        link.command(*frame(c))
        if c >= total - 1:
            return
        if link.lockstep:
            feedback = link.lockstep_feedback()
            c += 1
            if feedback is None and c % m == 0:
                run.lost_samples += 1
        else:
            feedback = link.next_feedback()
            received = time.monotonic()
            if feedback is None:
                raise DriveCommunicationError(
                    f"{link.where}: no feedback for {station.frame_timeout_s:g} s during "
                    f"'{excitation.name}' (frame_timeout_s in {station.source})")
            steps = max(1, round((feedback.stamp_s - stamp) / period_s))
            stamp = feedback.stamp_s
            run.lost_samples += sum(1 for p in range(c + 1, min(c + steps, total))
                                    if p % m == 0)
            if link.backlog():
                run.late_commands += 1
            c += steps
            if c >= total:
                return
        if run.lost_samples > allowed:
            raise DriveCommunicationError(
                f"{link.where}: {run.lost_samples} of {n} rows of '{excitation.name}' lost "
                f"(lost_sample_fraction {station.lost_sample_fraction:g} in {station.source})")


def _check_row(excitation: Excitation, states: OdriveStateMachine, feedback: Feedback,
               time_s: float, envelope: MotionEnvelope) -> None:
    violation = envelope.violation(position_rad=rad(feedback.position_turns),
                                   velocity_rad_s=rad(feedback.velocity_turns_s),
                                   time_s=time_s, excitation=excitation.name)
    if violation is not None:
        raise violation
    link = states.link
    active = link.errors[0] if link.errors is not None else 0
    beat = link.heartbeat
    if (beat is not None and beat.axis_error) or active:
        error = states.fault(f"at t = {time_s:.3f} s of '{excitation.name}'")
        if error is not None:
            raise error
        raise DriveStateError(f"{link.where}: active errors {error_names(active)} at "
                              f"t = {time_s:.3f} s of '{excitation.name}'")
    if beat is not None and beat.axis_state != AxisState.CLOSED_LOOP_CONTROL:
        raise DriveStateError(f"{link.where}: the axis left closed loop (heartbeat state "
                              f"{beat.axis_state}) at t = {time_s:.3f} s of "
                              f"'{excitation.name}'")


def late_commands(excitation: Excitation, run: StreamedRun, where: str,
                  source: str) -> DriveError | None:
    """A realtime run whose host answered too many sets late is not the planned
    excitation."""
    if run.late_commands <= MAX_LATE_FRACTION * max(len(run.rows), 1):
        return None
    return DriveCommunicationError(
        f"{where}: '{excitation.name}': {run.late_commands} of {len(run.rows)} commands went "
        f"out a feedback period late (more than {MAX_LATE_FRACTION:.0%}): the host could not "
        f"keep up; raise encoder_period_ms (and the ODrive's rates) in {source} or unload "
        "the machine")


def to_recording(excitation: Excitation, run: StreamedRun, states: OdriveStateMachine,
                 info: DriveInfo) -> Recording:
    """The rows of a run as a :class:`Recording` (rad, rad/s, N·m, A), with metadata
    stating how they were timed and which torque they carry."""
    station = states.station
    rows = run.rows
    fs = excitation.fs_hz

    def column(values: list[float]) -> np.ndarray:
        return np.asarray(values, dtype=np.float64)

    source = station.torque_source
    if source == "estimate":
        torque = [f.torque_estimate_nm for _, _, f in rows]
    elif source == "target":
        torque = [f.torque_target_nm for _, _, f in rows]
    else:
        torque = [station.torque_constant_nm_a * f.iq_measured_a for _, _, f in rows]
    columns = {
        "time_s": column([k / fs for k, _, _ in rows]),
        "position_rad": column([rad(f.position_turns) for _, _, f in rows]),
        "velocity_rad_s": column([rad(f.velocity_turns_s) for _, _, f in rows]),
        "torque_nm": column(torque),
        "current_a": column([f.iq_measured_a for _, _, f in rows]),
        COMMAND_COLUMN[excitation.mode]: column([cmd for _, cmd, _ in rows]),
    }
    period_s = station.feedback_period_s
    pacing = ("lockstep: the host steps the emulator one feedback period per command "
              "(emulator only)" if station.pacing == "lockstep"
              else "realtime: the ODrive's own clock")
    metadata = {
        "drive": states.link.where,
        "node_id": str(station.node_id),
        **info.identity(),
        "excitation": excitation.name,
        "control_mode": excitation.mode.value,
        "acquisition": (f"streamed CANSimple cyclic messages every {period_s * 1e3:g} ms "
                        f"({pacing}); row k = the feedback set of period "
                        f"{decimation(excitation, period_s)}·k, time_s = k/fs from the "
                        "drive's period count; each period's setpoint (Set_Input_*, "
                        "passthrough) sent half a period after its set with the command at "
                        "the next period's start: stairs centred on their sample times"),
        "pacing": station.pacing,
        "feedback_period_s": f"{period_s:g}",
        "torque_source": TORQUE_SOURCE_TEXT[source],
        "torque_constant_nm_a": f"{station.torque_constant_nm_a:g}",
        "torque_sample": "instantaneous",
        "torque_reports": TORQUE_REPORTS[source],
        "position_latch": "unknown",
        "control_period_s": f"{station.control_period_s:g}",
        "command_interpolation": "hold",
        "lost_samples": str(run.lost_samples),
        "late_commands": str(run.late_commands),
        **excitation.metadata,
    }
    return Recording(columns=columns, metadata=metadata, source=f"odrive:{excitation.name}")
