"""The drive-recorder path over Modbus: for rates the poll cannot reach.

The command is written as a waveform table (``recorder_index`` and a window of
``recorder_waveform``, one request per window), the drive plays it at its control rate
(``1 / control_period_s``, divided by ``recorder_divider``) while capturing position,
velocity, torque and current per table sample; the host meanwhile polls the feedback
(fault, enable, the motion monitor) and the recorder's state, keeps the held axes' watchdogs
fed, and afterwards reads the captures back a window at a time (the index written, then the
capture windows and the index in one read, so each block says which samples it holds).
Where the map has them: a run's torque offset is written as the offset table and played
with the command (the drive adds it sample by sample), and at a divider above 1 the drive
captures the torque's mean over each sample's control periods (the station's
``torque_sample``, as for the polled ``torque_mean``: the recording says ``mean`` and its
``torque_mean_period_s``), which the point sample of a 4 kHz torque aliases.
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
    RECORDER_OFFSET,
    RECORDER_SAMPLES,
    RECORDER_START,
    RECORDER_START_WITH_OFFSET,
    RECORDER_STATE,
    RECORDER_TORQUE_MEAN,
    RECORDER_TORQUE_SAMPLE,
    RECORDER_WAVEFORM,
    TORQUE_OFFSET,
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


def plays_torque_offset(link: ModbusLink) -> bool:
    """The recorder plays a torque offset table (the map's ``recorder_offset``)."""
    return RECORDER_OFFSET in link.map.registers


def recorder_refusal(excitation: Excitation, *, rate_hz: float, capacity: int,
                     torque_offset: bool = False) -> str | None:
    """Why ``excitation`` cannot be played on a recorder of ``capacity`` samples at
    ``rate_hz / n`` (``torque_offset``: one that plays a torque offset table), or ``None``."""
    refused = Recorder(stream_rate_hz=0.0, samples=capacity,
                       torque_offset=torque_offset).refuses(excitation)
    if refused is not None:
        return refused
    divider = rate_hz / excitation.fs_hz
    if divider < 1 - 1e-9 or abs(divider - round(divider)) > 1e-9:
        return (f"'{excitation.name}' at {excitation.fs_hz:g} Hz: the drive recorder samples "
                f"at {rate_hz:g} Hz / n")
    return None


def _raw_table(link: ModbusLink, excitation: Excitation, values: np.ndarray, *,
               window: str, units: str) -> np.ndarray:
    """``values`` in the units of the register ``units``, as the window ``window`` holds
    them.

    Raises
    ------
    DriveStateError
        A sample the window cannot hold.
    """
    scale = link.map[units].scale
    raw = np.round(np.asarray(values, dtype=np.float64) / scale)
    low, high = link.map[window].raw_range
    if raw.size and (raw.min() < low or raw.max() > high):
        raise DriveStateError(
            f"{link.where}: '{excitation.name}' exceeds what '{window}' holds "
            f"({low:g} … {high:g} × {scale:g})")
    return raw


def write_table(link: ModbusLink, raw: np.ndarray,
                keepalive: Callable[[], None] = lambda: None, *,
                window: str = RECORDER_WAVEFORM) -> None:
    """The table, a window per request (``recorder_index`` and the waveform window
    together; the index, then the window, for a window that does not follow the index);
    ``keepalive`` between them (the held axes' watchdogs)."""
    index, values = link.map[RECORDER_INDEX], link.map[window]
    after_index = index.address + index.count == values.address
    for start in range(0, len(raw), values.length):
        keepalive()
        words = values.encode_raw(raw[start : start + values.length])
        if after_index:
            link.write_words(index.address, index.encode(start) + words,
                             f"{window} samples {start}…")
        else:
            link.write_words(index.address, index.encode(start), f"{RECORDER_INDEX} {start}")
            link.write_words(values.address, words, f"{window} samples {start}…")


def play(link: ModbusLink, feedback: Feedback, excitation: Excitation, *, rate_hz: float,
         divider: int, envelope: MotionEnvelope, keepalive: Callable[[], None],
         torque_mean: bool = False) -> None:
    """Write ``excitation`` as the table (each sample held over ``divider`` control
    periods) with its torque offset as the offset table, start it, and watch the drive
    until it ends. ``torque_mean``: capture the torque's mean over each sample's control
    periods (:func:`captures_mean`).

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
    units = f"{excitation.mode.value}_cmd"
    raw = _raw_table(link, excitation, excitation.command, window=RECORDER_WAVEFORM,
                     units=units)
    write_table(link, raw, keepalive)
    start = RECORDER_START
    if excitation.torque_offset_nm is not None:
        offsets = _raw_table(link, excitation, excitation.torque_offset_nm,
                             window=RECORDER_OFFSET, units=TORQUE_OFFSET)
        write_table(link, offsets, keepalive, window=RECORDER_OFFSET)
        start = RECORDER_START_WITH_OFFSET
    link.write_value(RECORDER_LENGTH, float(len(raw)))
    link.write_value(RECORDER_DIVIDER, float(divider))
    if RECORDER_TORQUE_SAMPLE in link.map.registers:
        link.write_value(RECORDER_TORQUE_SAMPLE,
                         float(RECORDER_TORQUE_MEAN if captures_mean(torque_mean, divider)
                               else 0))
    try:
        link.write_value(RECORDER_CONTROL, float(start))
    except DriveFaultError as exc:
        raise DriveStateError(f"{link.where}: the drive refused to play '{excitation.name}' "
                              f"on its recorder ({exc})") from exc
    t0 = time.monotonic()
    # what the drive's setpoint goes to after the table: where it ended, or rest
    scale = link.map[units].scale
    link.write_value(units, float(raw[-1]) * scale if excitation.mode is Mode.POSITION else 0.0)
    duration_s = len(raw) * divider / rate_hz
    log.info("%s: %s on the drive recorder (%d samples at %g Hz, %.2f s)", link.where,
             excitation.name, len(raw), rate_hz / divider, duration_s)
    deadline = t0 + duration_s + FINISH_MARGIN_S
    while True:
        # the recorder's state before the status: a fault that aborts the recorder between
        # the two reads then shows as the fault it is, not as an aborted recorder (CI,
        # session 29: the status read just before the fault, the state just after)
        state = round(link.read_values((RECORDER_STATE,))[RECORDER_STATE])
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


def captures_mean(torque_mean: bool, divider: int) -> bool:
    """The torque captured is the mean over each sample's ``divider`` control periods:
    asked for, and more than one period (one period's mean is its torque)."""
    return torque_mean and divider > 1


def upload(link: ModbusLink, excitation: Excitation, info: DriveInfo, *, rate_hz: float,
           divider: int, keepalive: Callable[[], None] = lambda: None,
           torque_mean: bool = False) -> Recording:
    """What the recorder captured of ``excitation`` (all of it after a finished run, the
    samples up to the stop after an aborted one), a capture window per read; ``keepalive``
    between windows (the held axes' watchdogs: 16 384 samples take about 1-2 s).
    ``torque_mean``: as given to :func:`play` (the recording says which torque it holds).

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
    if captures_mean(torque_mean and RECORDER_TORQUE_SAMPLE in m.registers, divider):
        # the mean over the sample's periods up to and including the captured one: the
        # streamed torque_mean's definition, over divider periods
        torque = {"torque_sample": "mean", "torque_mean_period_s": f"{divider * control_s:g}"}
    else:
        torque = {"torque_sample": "instantaneous"}
    metadata = {
        **run_identity(link, info, excitation),
        # row k: control period k·n of the table's play (position at its start, the
        # torque commanded over it), timed by the drive's loop
        "acquisition": "drive recorder",
        "recorder_divider": str(divider),
        "requested_rate_hz": f"{excitation.fs_hz:g}",
        "control_period_s": f"{control_s:g}",
        **torque,
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

