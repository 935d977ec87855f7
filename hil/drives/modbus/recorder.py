"""The drive-recorder path over Modbus: for rates the poll cannot reach.

The command is written as a waveform table (``recorder_index`` and a window of
``recorder_waveform``, one request per window), the drive plays it at its control rate
(``1 / control_period_s``, divided by ``recorder_divider``) while capturing position,
velocity, torque and current per table sample; the host meanwhile polls the feedback
(fault, enable, the motion monitor) and the recorder's state, keeps the held axes' watchdogs
fed, and afterwards reads the captures back a window at a time (the index written, then the
capture windows and the index in one read, so each block says which samples it holds).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import numpy as np

from hil.drives.base import DriveInfo, MotionEnvelope, Recorder
from hil.drives.modbus.acquire import Feedback, run_identity
from hil.drives.modbus.link import ModbusLink
from hil.drives.modbus.regmap import (
    RECORDER_ABORTED,
    RECORDER_BUSY,
    RECORDER_CAPACITY,
    RECORDER_COLUMNS,
    RECORDER_CONTROL,
    RECORDER_DIVIDER,
    RECORDER_DONE,
    RECORDER_INDEX,
    RECORDER_LENGTH,
    RECORDER_SAMPLES,
    RECORDER_START,
    RECORDER_STATE,
    RECORDER_WAVEFORM,
)
from hil.errors import DriveCommunicationError, DriveFaultError, DriveStateError
from hil.motion import COMMAND_COLUMN, Excitation, Mode
from hil.recording import Recording

log = logging.getLogger(__name__)

POLL_S = 0.01  # the host's watch over the drive while the table plays
FINISH_MARGIN_S = 1.0  # beyond the table's own duration before "did not finish"
STATE_NAMES = {0: "idle", RECORDER_BUSY: "busy", RECORDER_DONE: "done",
               RECORDER_ABORTED: "aborted"}


def recorder_capacity(link: ModbusLink) -> int:
    """The samples the drive's recorder holds (its ``recorder_capacity`` register)."""
    return round(link.read_values((RECORDER_CAPACITY,))[RECORDER_CAPACITY])


def recorder_refusal(excitation: Excitation, *, rate_hz: float, capacity: int) -> str | None:
    """Why ``excitation`` cannot be played on a recorder of ``capacity`` samples at
    ``rate_hz / n``, or ``None``."""
    refused = Recorder(stream_rate_hz=0.0, samples=capacity).refuses(excitation)
    if refused is not None:
        return refused
    divider = rate_hz / excitation.fs_hz
    if divider < 1 - 1e-9 or abs(divider - round(divider)) > 1e-9:
        return (f"'{excitation.name}' at {excitation.fs_hz:g} Hz: the drive recorder samples "
                f"at {rate_hz:g} Hz / n")
    return None


def _raw_table(link: ModbusLink, excitation: Excitation) -> np.ndarray:
    """The command in the played mode's ``*_cmd`` units, as the waveform register holds it.

    Raises
    ------
    DriveStateError
        A sample the waveform register cannot hold.
    """
    scale = link.map[f"{excitation.mode.value}_cmd"].scale
    raw = np.round(np.asarray(excitation.command, dtype=np.float64) / scale)
    low, high = link.map[RECORDER_WAVEFORM].raw_range
    if raw.size and (raw.min() < low or raw.max() > high):
        raise DriveStateError(
            f"{link.where}: '{excitation.name}' exceeds what '{RECORDER_WAVEFORM}' holds "
            f"({low:g} … {high:g} × {scale:g})")
    return raw


def write_table(link: ModbusLink, raw: np.ndarray,
                keepalive: Callable[[], None] = lambda: None) -> None:
    """The table, a window per request (``recorder_index`` and the window together);
    ``keepalive`` between them (the held axes' watchdogs)."""
    index, waveform = link.map[RECORDER_INDEX], link.map[RECORDER_WAVEFORM]
    for start in range(0, len(raw), waveform.length):
        keepalive()
        words = index.encode(start) + waveform.encode_raw(raw[start : start + waveform.length])
        link.write_words(index.address, words, f"waveform samples {start}…")


def play(link: ModbusLink, feedback: Feedback, excitation: Excitation, *, rate_hz: float,
         divider: int, envelope: MotionEnvelope, keepalive: Callable[[], None]) -> None:
    """Write ``excitation`` as the table (each sample held over ``divider`` control
    periods), start it, and watch the drive until it ends.

    Raises
    ------
    DriveStateError
        The drive refused the table or the start (nothing moved), disabled itself, or the
        recorder aborted or did not finish in time.
    DriveFaultError
        The drive faulted while playing.
    LimitViolationError
        The position or velocity polled meanwhile left ``envelope`` (the caller
        quick-stops the drive).
    DriveCommunicationError
        A request failed.
    """
    raw = _raw_table(link, excitation)
    write_table(link, raw, keepalive)
    link.write_value(RECORDER_LENGTH, float(len(raw)))
    link.write_value(RECORDER_DIVIDER, float(divider))
    try:
        link.write_value(RECORDER_CONTROL, float(RECORDER_START))
    except DriveFaultError as exc:
        raise DriveStateError(f"{link.where}: the drive refused to play '{excitation.name}' "
                              f"on its recorder ({exc})") from exc
    t0 = time.monotonic()
    # what the drive's setpoint goes to after the table: where it ended, or rest
    scale = link.map[f"{excitation.mode.value}_cmd"].scale
    link.write_value(f"{excitation.mode.value}_cmd",
                     float(raw[-1]) * scale if excitation.mode is Mode.POSITION else 0.0)
    duration_s = len(raw) * divider / rate_hz
    log.info("%s: %s on the drive recorder (%d samples at %g Hz, %.2f s)", link.where,
             excitation.name, len(raw), rate_hz / divider, duration_s)
    deadline = t0 + duration_s + FINISH_MARGIN_S
    while True:
        stamp, values = feedback.read()
        violation = envelope.violation(
            position_rad=values["position"], velocity_rad_s=values["velocity"],
            time_s=stamp - t0, excitation=excitation.name)
        if violation is not None:
            raise violation
        if feedback.bit(values, "fault"):
            raise DriveFaultError(
                f"{link.where}: drive fault at t = {stamp - t0:.3f} s of '{excitation.name}' "
                "(drive recorder)", code=int(values["fault_code"]))
        state = round(link.read_values((RECORDER_STATE,))[RECORDER_STATE])
        if state == RECORDER_DONE:
            return
        if not feedback.bit(values, "enabled"):
            raise DriveStateError(f"{link.where}: drive disabled itself during "
                                  f"'{excitation.name}' (drive recorder)")
        if state != RECORDER_BUSY:
            raise DriveStateError(f"{link.where}: the drive recorder is "
                                  f"{STATE_NAMES.get(state, str(state))} during "
                                  f"'{excitation.name}'")
        if time.monotonic() > deadline:
            raise DriveStateError(f"{link.where}: the drive recorder did not finish "
                                  f"'{excitation.name}' in {duration_s + FINISH_MARGIN_S:.2f} s")
        keepalive()
        time.sleep(max(0.0, POLL_S - (time.monotonic() - stamp)))


def upload(link: ModbusLink, excitation: Excitation, info: DriveInfo, *, rate_hz: float,
           divider: int, keepalive: Callable[[], None] = lambda: None) -> Recording:
    """What the recorder captured of ``excitation`` (all of it after a finished run, the
    samples up to the stop after an aborted one), a capture window per read; ``keepalive``
    between windows (the held axes' watchdogs: 16 384 samples take about 1-2 s).

    Raises
    ------
    DriveCommunicationError
        A request failed, or a block did not hold the samples asked for.
    """
    m = link.map
    count = round(link.read_values((RECORDER_SAMPLES,))[RECORDER_SAMPLES])
    count = min(count, len(excitation.command))
    index = m[RECORDER_INDEX]
    columns = {name: m[register] for name, register in RECORDER_COLUMNS.items()}
    block = m.blocks((*RECORDER_COLUMNS.values(), RECORDER_INDEX))
    window = m.capture_window
    raw: dict[str, list[np.ndarray]] = {name: [] for name in columns}
    for start in range(0, count, window):
        keepalive()
        link.write_value(RECORDER_INDEX, float(start))
        words = link.read_words(block)
        got = round(index.decode([words[index.address + i] for i in range(index.count)]))
        if got != start:
            raise DriveCommunicationError(f"{link.where}: recorder block at sample {start} "
                                          f"read back as sample {got}")
        take = min(window, count - start)
        for name, register in columns.items():
            values = register.decode_raw([words[register.address + i]
                                          for i in range(register.words)])
            raw[name].append(values[:take] * register.scale)

    def column(name: str) -> np.ndarray:
        return (np.concatenate(raw[name]) if raw[name] else np.zeros(0)).astype(np.float64)

    control_s = 1.0 / rate_hz
    metadata = {
        **run_identity(link, info, excitation),
        # row k: control period k·n of the table's play (position at its start, the
        # torque commanded over it), timed by the drive's loop
        "acquisition": "drive recorder",
        "recorder_divider": str(divider),
        "requested_rate_hz": f"{excitation.fs_hz:g}",
        "control_period_s": f"{control_s:g}",
        "torque_sample": "instantaneous",
        "command_interpolation": "hold",  # each table sample held over its periods
        **excitation.metadata,
    }
    return Recording(
        columns={
            "time_s": np.arange(count) / excitation.fs_hz,
            "position_rad": column("position"),
            "velocity_rad_s": column("velocity"),
            "torque_nm": column("torque"),
            COMMAND_COLUMN[excitation.mode]: np.asarray(excitation.command[:count],
                                                        dtype=np.float64),
            "current_a": column("current"),
        },
        metadata=metadata,
        source=f"modbus-recorder:{excitation.name}",
    )


def recorder_rate_hz(link: ModbusLink) -> float:
    """The recorder's rate: the drive's control rate (the map's ``control_period_s``)."""
    period = link.map.control_period_s
    return 0.0 if period is None or not link.map.has_recorder else 1.0 / period

