"""Acquisition over CANopen: SYNC-clocked PDO streaming, and the drive-recorder path.

Streaming: command sample k travels in the RPDO sent before SYNC k, the drive applies it
at SYNC k, and the TPDOs answering SYNC k are recording row k, timed ``k × period`` from
the SYNC count (never from host clocks). The recorder path is for rates a bus cannot
stream: the command is downloaded as a waveform table (0x2100), played by the drive at
its loop rate and sampled by its trace recorder (0x2200), uploaded by segmented SDO.
"""

from __future__ import annotations

import logging
import math
import struct
from typing import Protocol

import numpy as np

from hil.drives.base import DriveInfo
from hil.drives.cia402.link import CanLink
from hil.drives.cia402.protocol import (
    CW_DISABLE_VOLTAGE,
    CW_ENABLE_OPERATION,
    SW_FAULT,
    TARGET_OBJECT,
    TORQUE_MEAN_PER_RATED,
    Scaling,
    state_of,
)
from hil.drives.station import CanOpenStation
from hil.errors import DriveCommunicationError, DriveError, DriveFaultError, DriveStateError
from hil.motion import COMMAND_COLUMN, Excitation, Limits, Mode
from hil.recording import Recording

log = logging.getLogger(__name__)

MAX_CONSECUTIVE_LOST = 25
RECORDER_SAMPLE = np.dtype([("pos", "<i4"), ("vel", "<i4"), ("torque", "<i2"), ("current", "<i2")])
_LIMITS = {"h": (-32768, 32767), "i": (-(2**31), 2**31 - 1)}


class AcquiringDrive(Protocol):
    """What acquisition uses of a connected CiA 402 drive, and nothing else: the link, the
    station and scaling it connected with, what it learnt of the drive, and how to make it
    safe after a failed run."""

    link: CanLink
    station: CanOpenStation
    scaling: Scaling | None
    limits: Limits
    torque_sample: str  # "mean" (0x2077) or "instantaneous" (0x6077)
    command_interpolation: str
    control_period_s: float | None
    recorder_rate_hz: float

    @property
    def info(self) -> DriveInfo: ...

    def comm_error(self, message: str) -> DriveCommunicationError: ...

    def mark_faulted(self) -> None: ...

    def quick_stop(self) -> None: ...

    def disable(self) -> None: ...


class _FaultedError(Exception):
    def __init__(self, time_s: float) -> None:
        super().__init__(time_s)
        self.time_s = time_s


def _raw_command(drive: AcquiringDrive, excitation: Excitation) -> np.ndarray:
    assert drive.scaling is not None
    sc, mode = drive.scaling, excitation.mode
    factor = {
        Mode.VELOCITY: sc.velocity_units_per_rad_s,
        Mode.TORQUE: 1e3 / sc.rated_torque_nm,
        Mode.POSITION: sc.counts_per_rad,
    }[mode]
    low, high = _LIMITS[TARGET_OBJECT[mode][1]]
    return np.clip(np.round(np.asarray(excitation.command) * factor), low, high).astype(np.int64)


def _metadata(drive: AcquiringDrive, excitation: Excitation, **extra: str) -> dict[str, str]:
    info, st = drive.info, drive.station
    return {
        "drive": f"canopen node {st.node_id}",
        "node_id": str(st.node_id),
        "vendor": info.vendor,
        "model": info.model,
        "firmware": info.firmware_version,
        "serial": info.serial,
        "transport": info.transport,
        "excitation": excitation.name,
        "control_mode": excitation.mode.value,
        "operation_mode": str(getattr(drive, "mode_code", "")),
        **extra,
        **excitation.metadata,
    }


def run_stream(drive: AcquiringDrive, excitation: Excitation) -> Recording:
    link, st = drive.link, drive.station
    assert drive.scaling is not None
    sc, mode = drive.scaling, excitation.mode
    raw = _raw_command(drive, excitation)
    cob, _ = link.rpdo_payload(mode, CW_ENABLE_OPERATION, 0)
    packer = struct.Struct("<H" + TARGET_OBJECT[mode][1])
    counts_margin = 0.05 * sc.counts_per_rad  # the drive's own 0x607D acts first
    travel = (
        drive.limits.travel_min_rad * sc.counts_per_rad - counts_margin,
        drive.limits.travel_max_rad * sc.counts_per_rad + counts_margin,
    )
    link.forget()
    first = link.sync_index + 1
    error: DriveError | None = None
    log.info(
        "node %d: streaming %s (%d samples at %.0f Hz)",
        st.node_id,
        excitation.name,
        len(raw),
        1 / st.sync_period_s,
    )
    try:
        with link.direct_receive():
            done = _stream_loop(drive, excitation, raw, cob, packer, travel)
    except _FaultedError as fault:
        # 0x603F by SDO: only now that the Notifier receives again
        code = link.emcy[-1][0] if link.emcy else link.fault_code()
        error = DriveFaultError(
            f"node {st.node_id} faulted at t = {fault.time_s:.3f} s of '{excitation.name}' "
            f"({'EMCY' if link.emcy else 'statusword fault bit, 0x603F'})",
            code=code,
        )
        done = link.sync_index - first + 1
    except DriveError as exc:
        error = exc
        done = link.sync_index - first + 1
    except BaseException:
        drive.quick_stop()
        raise
    recording = _stream_recording(drive, excitation, raw, first, done)
    if error is not None:
        _make_safe(drive, error)
        error.partial_recording = recording
        raise error
    link.target = 0 if mode is not Mode.POSITION else int(raw[-1])
    link.tick()
    lost = len(raw) - len(recording)
    if lost > st.lost_sample_fraction * len(raw):
        comm = drive.comm_error(
            f"lost {lost} of {len(raw)} samples of '{excitation.name}' (limit "
            f"{st.lost_sample_fraction:.1%})"
        )
        comm.partial_recording = recording
        raise comm
    return recording


def _stream_loop(
    drive: AcquiringDrive,
    excitation: Excitation,
    raw: np.ndarray,
    cob: int,
    packer: struct.Struct,
    travel: tuple[float, float],
) -> int:
    """The cyclic exchange; returns the number of SYNCs sent."""
    link, st = drive.link, drive.station
    assert drive.scaling is not None
    sc = drive.scaling
    period_s = st.sync_period_s
    lost_in_a_row = 0
    done = 0
    for k in range(len(raw)):
        answered = link.tick(cob, packer.pack(CW_ENABLE_OPERATION, int(raw[k])))
        done = k + 1
        if not answered:
            lost_in_a_row += 1
            if lost_in_a_row > MAX_CONSECUTIVE_LOST:
                link.check()
                raise drive.comm_error(
                    f"no feedback PDOs for {lost_in_a_row} SYNC periods "
                    f"(at t = {k * period_s:.3f} s of '{excitation.name}')"
                )
            continue
        lost_in_a_row = 0
        statusword, position, _ = struct.unpack("<Hib", link.rx1[link.sync_index])
        if statusword & SW_FAULT or link.emcy:
            raise _FaultedError(k * period_s)
        if statusword & 0x6F != 0x27:
            raise DriveStateError(
                f"node {st.node_id} left OPERATION ENABLED ({state_of(statusword)}) at "
                f"t = {k * period_s:.3f} s of '{excitation.name}'"
            )
        if not travel[0] <= position <= travel[1]:
            raise DriveStateError(
                f"position {position / sc.counts_per_rad:.3f} rad left the travel limits "
                f"during '{excitation.name}'"
            )
    return done


def _stream_recording(
    drive: AcquiringDrive, excitation: Excitation, raw: np.ndarray, first: int, done: int
) -> Recording:
    link = drive.link
    assert drive.scaling is not None
    sc = drive.scaling
    rows = [k for k in range(done) if first + k in link.rx1 and first + k in link.rx2]
    one, two = link.decode([first + k for k in rows])
    k_arr = np.asarray(rows, dtype=np.int64)
    pos = np.asarray([r[1] for r in one], dtype=np.float64)
    vel = np.asarray([r[0] for r in two], dtype=np.float64)
    torque = np.asarray([r[1] for r in two], dtype=np.float64)
    current = np.asarray([r[2] for r in two], dtype=np.float64)
    period = 1.0 / excitation.fs_hz  # the SYNC period of this run (written by drive.run)
    mean = drive.torque_sample == "mean"
    torque_per_rated = TORQUE_MEAN_PER_RATED if mean else 1e3  # 0x2077: 0.1 ‰, 0x6077: ‰
    columns = {
        "time_s": k_arr * period,
        "position_rad": pos / sc.counts_per_rad,
        "velocity_rad_s": vel / sc.velocity_units_per_rad_s,
        "torque_nm": torque * sc.rated_torque_nm / torque_per_rated,
        COMMAND_COLUMN[excitation.mode]: np.asarray(
            [sc.to_si(excitation.mode, float(v)) for v in raw[k_arr]], dtype=np.float64
        ),
        "current_a": current * sc.rated_current_a / 1e3,
    }
    timing = {
        # row k: the drive's last control-loop sample before SYNC k (position measured at
        # its start, torque commanded over it), or with "mean" the torque averaged over the
        # control periods of the SYNC period before SYNC k (0x2077); the targets are
        # interpolated as stated
        "torque_sample": drive.torque_sample,
        "command_interpolation": drive.command_interpolation,
    }
    if mean:
        timing["torque_mean_period_s"] = f"{period:g}"
    if drive.control_period_s is not None:
        timing["control_period_s"] = f"{drive.control_period_s:g}"
    metadata = _metadata(
        drive,
        excitation,
        acquisition="sync stream",
        sync_period_s=f"{period:g}",
        lost_samples=str(done - len(rows)),
        **timing,
    )
    floats = {name: np.asarray(values, dtype=np.float64) for name, values in columns.items()}
    return Recording(columns=floats, metadata=metadata, source=f"canopen:{excitation.name}")


def _make_safe(drive: AcquiringDrive, error: DriveError) -> None:
    """After a fault: power off (the drive already is in FAULT); otherwise quick stop."""
    link = drive.link
    if isinstance(error, DriveFaultError):
        drive.mark_faulted()
        link.controlword = CW_DISABLE_VOLTAGE
        try:
            link.tick()
        except DriveError as exc:
            log.error("node %d: %s", drive.station.node_id, exc)
        return
    drive.quick_stop()
    drive.disable()


def run_recorder(drive: AcquiringDrive, excitation: Excitation) -> Recording:
    link, st = drive.link, drive.station
    assert drive.scaling is not None
    sc = drive.scaling
    divider = round(drive.recorder_rate_hz / excitation.fs_hz)
    wave = np.repeat(_raw_command(drive, excitation), divider).astype("<i4")
    capacity = int(link.read(0x2200, 5))
    if len(excitation.command) > capacity:
        raise DriveStateError(
            f"'{excitation.name}' has {len(excitation.command)} samples; the drive recorder "
            f"holds {capacity}"
        )
    link.write(0x2100, 1, wave.tobytes())
    link.write(0x2200, 3, divider)
    link.write(0x2200, 1, 1)
    loop_s = 1.0 / drive.recorder_rate_hz
    ticks = math.ceil(len(wave) * loop_s / st.sync_period_s) + 1
    error: DriveError | None = None
    try:
        for tick in range(ticks):
            link.tick()
            status = link.latest_status()
            if status is not None and (status[0] & SW_FAULT or link.emcy):
                raise DriveFaultError(
                    f"node {st.node_id} faulted at t = {tick * st.sync_period_s:.3f} s of "
                    f"'{excitation.name}' (EMCY, drive recorder)",
                    code=(link.emcy[-1][0] if link.emcy else 0) or link.fault_code(),
                )
        if int(link.read(0x2200, 2)) != 2:
            raise DriveStateError(f"drive recorder did not finish '{excitation.name}'")
    except DriveError as exc:
        error = exc
    except BaseException:
        drive.quick_stop()
        raise
    data = bytes(link.read(0x2200, 7)) if link.connected else b""
    samples = np.frombuffer(data[: len(data) // 12 * 12], dtype=RECORDER_SAMPLE)
    n = len(samples)
    columns = {
        "time_s": np.arange(n) / excitation.fs_hz,
        "position_rad": np.asarray(samples["pos"] / sc.counts_per_rad, dtype=np.float64),
        "velocity_rad_s": np.asarray(
            samples["vel"] / sc.velocity_units_per_rad_s, dtype=np.float64
        ),
        "torque_nm": np.asarray(samples["torque"] * sc.rated_torque_nm / 1e3, dtype=np.float64),
        COMMAND_COLUMN[excitation.mode]: np.asarray(excitation.command[:n], dtype=np.float64),
        "current_a": np.asarray(samples["current"] * sc.rated_current_a / 1e3, dtype=np.float64),
    }
    recording = Recording(
        columns=columns,
        metadata=_metadata(
            drive,
            excitation,
            acquisition="drive recorder",
            recorder_divider=str(divider),
            control_period_s=f"{1.0 / drive.recorder_rate_hz:g}",
            torque_sample="instantaneous",
            command_interpolation="hold",  # the waveform table repeats each command sample
        ),
        source=f"canopen-recorder:{excitation.name}",
    )
    if error is not None:
        _make_safe(drive, error)
        error.partial_recording = recording
        raise error
    return recording
