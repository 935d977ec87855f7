"""Acquisition over CANopen: SYNC-clocked PDO streaming, and the drive-recorder path.

Streaming: command sample k travels in the RPDO sent before SYNC k, the drive applies it
at SYNC k, and the TPDOs answering SYNC k are recording row k, timed ``k × period`` from
the SYNC count (never from host clocks). The recorder path is for rates a bus cannot
stream: the command is downloaded as a waveform table, played by the drive at its loop
rate and sampled by its trace recorder, uploaded by segmented SDO (where the object map
puts them: the emulator's 0x2100 and 0x2200).
"""

from __future__ import annotations

import logging
import math
import struct
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from hil.drives.base import MotionEnvelope, Recorder
from hil.drives.cia402.link import CanLink
from hil.drives.cia402.protocol import (
    CW_ENABLE_OPERATION,
    CW_QUICK_STOP,
    RPDO_FORMAT,
    SW_FAULT,
    TARGET_OBJECT,
    Scaling,
    state_of,
)
from hil.drives.realtime import collector_held
from hil.errors import (
    DriveCommunicationError,
    DriveError,
    DriveFaultError,
    DriveStateError,
    LimitViolationError,
)
from hil.motion import COMMAND_COLUMN, Excitation, Mode
from hil.recording import Recording

log = logging.getLogger(__name__)

MAX_CONSECUTIVE_LOST = 25
SW_INTERNAL_LIMIT = 0x0800  # statusword bit 11: the drive stopped at one of its own limits
RECORDER_SAMPLE = np.dtype([("pos", "<i4"), ("vel", "<i4"), ("torque", "<i2"), ("current", "<i2")])
_LIMITS = {"h": (-32768, 32767), "i": (-(2**31), 2**31 - 1)}


@dataclass(frozen=True, slots=True, kw_only=True)
class RunSetup:
    """What acquisition needs of the connected drive besides its link, and nothing else.

    Attributes
    ----------
    node_id : int
        For messages.
    sync_period_s : float
        The station's SYNC period (messages; the recorder's wait in SYNC ticks).
    lost_sample_fraction : float
        Lost rows a streamed run may have before it is a communication error.
    scaling : Scaling
        Drive units <-> SI.
    envelope : MotionEnvelope
        The motion monitor's bounds: a streamed run whose measured position or velocity
        leaves them stops (a :class:`LimitViolationError`; the drive is then quick-stopped).
    torque_sample : str
        ``"mean"`` (the object map's ``torque_mean``, averaged over the SYNC period) or
        ``"instantaneous"`` (0x6077).
    torque_per_rated : float
        Counts of the streamed torque object per rated torque (0x6077: 1000).
    command_interpolation : str
        How the drive moves between cyclic targets (0x60C0), for the metadata.
    control_period_s : float or None
        The drive's control period, if known.
    recorder_rate_hz : float
        The drive recorder's sample rate (0: no recorder).
    recorder_index, waveform_index : int or None
        The object map's recorder and waveform table objects.
    conventions : dict of str to str
        What the object map says of the drive (:meth:`ObjectMap.conventions`), for the
        metadata.
    identity : dict of str to str
        The metadata naming the drive (drive, node, vendor, model, firmware, serial,
        transport).
    operation_mode : str
        The CiA 402 operation mode code (0x6060) the run is made in.
    """

    node_id: int
    sync_period_s: float
    lost_sample_fraction: float
    scaling: Scaling
    envelope: MotionEnvelope
    torque_sample: str
    torque_per_rated: float
    command_interpolation: str
    control_period_s: float | None
    recorder_rate_hz: float
    recorder_index: int | None
    waveform_index: int | None
    conventions: dict[str, str]
    identity: dict[str, str]
    operation_mode: str


class Follower(Protocol):
    """A gimbal's other axis that follows a path on its own drive recorder while the axis
    under test plays its run (:class:`hil.drives.cia402.held_axis.HeldAxis`)."""

    def play(self, path_rad: np.ndarray, *, divider: int) -> None:
        """Download the path and start it: it starts at the next SYNC."""

    def played_rad(self) -> np.ndarray:
        """Where it stood at each recorded sample of the path (rad)."""


@dataclass(frozen=True, slots=True)
class Acquired:
    """A run's recording, and the error that cut it short (then the drive must be made
    safe before the error, with this recording attached, is raised), or the stop signal
    that did (then the drive is quick-stopped and the signal re-raised with the rows)."""

    recording: Recording
    failure: DriveError | None = None
    stop: KeyboardInterrupt | None = None


class _FaultedError(Exception):
    def __init__(self, time_s: float) -> None:
        super().__init__(time_s)
        self.time_s = time_s


def _raw_command(setup: RunSetup, excitation: Excitation) -> np.ndarray:
    sc, mode = setup.scaling, excitation.mode
    factor = {
        Mode.VELOCITY: sc.velocity_units_per_rad_s,
        Mode.TORQUE: 1e3 / sc.rated_torque_nm,
        Mode.POSITION: sc.counts_per_rad,
    }[mode]
    low, high = _LIMITS[TARGET_OBJECT[mode][1]]
    return np.clip(np.round(np.asarray(excitation.command) * factor), low, high).astype(np.int64)


def _hold_where_it_ended(link: CanLink, mode: Mode, raw: np.ndarray) -> None:
    """The target the link holds after a run: the last position, else zero."""
    link.target = 0 if mode is not Mode.POSITION else int(raw[-1])


def _raw_offset(setup: RunSetup, excitation: Excitation) -> np.ndarray | None:
    """The torque offset (0x60B2, per-mille of the rated torque) of a velocity-mode run:
    zeros when the excitation sends none; ``None`` in the other modes' RPDOs.

    Raises
    ------
    DriveStateError
        A torque offset in a mode whose RPDO does not carry one.
    """
    if excitation.mode is not Mode.VELOCITY:
        if excitation.torque_offset_nm is not None:
            raise DriveStateError(f"excitation '{excitation.name}': a torque offset (0x60B2) "
                                  "is streamed in velocity mode only")
        return None
    if excitation.torque_offset_nm is None:
        return np.zeros(len(excitation.command), dtype=np.int64)
    per_mille = np.asarray(excitation.torque_offset_nm) * 1e3 / setup.scaling.rated_torque_nm
    return np.clip(np.round(per_mille), *_LIMITS["h"]).astype(np.int64)


def _metadata(setup: RunSetup, excitation: Excitation, **extra: str) -> dict[str, str]:
    return {
        **setup.identity,
        **setup.conventions,
        "excitation": excitation.name,
        "control_mode": excitation.mode.value,
        "operation_mode": setup.operation_mode,
        **extra,
        **excitation.metadata,
    }


def run_stream(link: CanLink, setup: RunSetup, excitation: Excitation) -> Acquired:
    """Stream ``excitation`` one sample per SYNC (the SYNC period already written).

    Parameters
    ----------
    link : CanLink
        The node's link, in OPERATIONAL, the drive enabled in the excitation's mode.
    setup : RunSetup
        What acquisition needs of the drive.
    excitation : Excitation
        The command, one sample per SYNC period.

    Returns
    -------
    Acquired
        The recording (row k timed ``k / fs`` from the SYNC count; rows whose TPDOs were
        lost are left out), and the error that cut the run short, if any.

    Raises
    ------
    DriveCommunicationError
        More than ``lost_sample_fraction`` of the rows were lost (the drive is left as it
        is, enabled; the recording attached).
    """
    mode = excitation.mode
    raw = _raw_command(setup, excitation)
    cob, _ = link.rpdo_payload(mode, CW_ENABLE_OPERATION, 0)
    packer = struct.Struct(RPDO_FORMAT[mode])
    offset = _raw_offset(setup, excitation)
    error: DriveError | None = None
    stop: KeyboardInterrupt | None = None
    log.info(
        "node %d: streaming %s (%d samples at %.0f Hz)",
        setup.node_id,
        excitation.name,
        len(raw),
        1 / setup.sync_period_s,
    )
    first = link.sync_index + 1
    tripped: int | None = None
    try:
        with link.direct_receive(), collector_held(), link.aligned_to_sync():
            link.forget()
            first = link.sync_index + 1  # (a SYNC producer other than the host runs on)
            try:
                done = _stream_loop(link, setup, excitation, raw, offset, cob, packer)
            except LimitViolationError:  # the axis runs away: stop it before all else
                tripped = link.sync_index  # the rows end here, not at the stop's SYNC
                _send_quick_stop(link, mode)
                raise
    except _FaultedError as fault:
        # 0x603F by SDO: only now that the Notifier receives again
        code = link.emcy[-1][0] if link.emcy else link.fault_code()
        error = DriveFaultError(
            f"node {setup.node_id} faulted at t = {fault.time_s:.3f} s of '{excitation.name}' "
            f"({'EMCY' if link.emcy else 'statusword fault bit, 0x603F'})",
            code=code,
        )
        done = link.sync_index - first + 1
    except DriveError as exc:
        error = exc
        done = (link.sync_index if tripped is None else tripped) - first + 1
    except KeyboardInterrupt as exc:  # a stop signal: keep the rows answered so far
        stop = exc
        done = max(0, min(len(raw), link.sync_index - first + 1))
    recording = _stream_recording(link, setup, excitation, raw, first, done)
    if error is not None or stop is not None:
        return Acquired(recording, error, stop)
    _hold_where_it_ended(link, mode, raw)
    link.tick()
    lost = len(raw) - len(recording)
    if lost > setup.lost_sample_fraction * len(raw):
        comm = DriveCommunicationError(
            f"node {setup.node_id}: lost {lost} of {len(raw)} samples of '{excitation.name}' "
            f"(limit {setup.lost_sample_fraction:.1%})"
        )
        comm.partial_recording = recording
        raise comm
    spread = spread_refusal(link, excitation)
    if spread is not None:
        spread.partial_recording = recording
        raise spread
    return Acquired(recording)


def _send_quick_stop(link: CanLink, mode: Mode) -> None:
    """The quick-stop controlword with a zero target, in the next SYNC's RPDO (the drive
    would otherwise hold the last target until the state machine's confirmed stop)."""
    link.controlword = CW_QUICK_STOP
    try:
        link.tick(*link.rpdo_payload(mode, CW_QUICK_STOP, 0))
    except DriveError as exc:
        log.error("node %d: quick stop not sent at the trip: %s", link.node_id, exc)


def spread_refusal(link: CanLink, excitation: Excitation) -> DriveCommunicationError | None:
    """The refusal of a realtime run whose SYNC intervals spread more than the station's
    ``max_sync_interval_sd_s`` (the rows are timed by the SYNC count, so the spread is
    error in their time axis), or ``None``."""
    st = link.station
    limit = st.max_sync_interval_sd_s
    spread = sync_spread_s(link.sync_sent_s, 1.0 / excitation.fs_hz)
    if limit is None or st.sync_pacing != "realtime" or spread is None or spread[0] <= limit:
        return None
    return DriveCommunicationError(
        f"node {st.node_id}: the SYNC intervals of '{excitation.name}' spread {spread[0]:.3g} s "
        f"(sd; largest error {spread[1]:.3g} s, {st.sync_producer} producer), more than the "
        f"station's max_sync_interval_sd_s {limit:g} s: the rows are timed by the SYNC count, "
        "so the spread is error in their time axis")


def _stream_loop(
    link: CanLink,
    setup: RunSetup,
    excitation: Excitation,
    raw: np.ndarray,
    offset: np.ndarray | None,
    cob: int,
    packer: struct.Struct,
) -> int:
    """The cyclic exchange; returns the number of SYNCs sent. Every answered SYNC's
    position and velocity go through the motion monitor (``setup.envelope``)."""
    sc = setup.scaling
    period_s = setup.sync_period_s
    lost_in_a_row = 0
    done = 0
    for k in range(len(raw)):
        fields = (CW_ENABLE_OPERATION, int(raw[k])) if offset is None else (
            CW_ENABLE_OPERATION, int(raw[k]), int(offset[k]))
        answered = link.tick(cob, packer.pack(*fields))
        done = k + 1
        if not answered:
            lost_in_a_row += 1
            if lost_in_a_row > MAX_CONSECUTIVE_LOST:
                link.check()
                raise DriveCommunicationError(
                    f"node {setup.node_id}: no feedback PDOs for {lost_in_a_row} SYNC periods "
                    f"(at t = {k * period_s:.3f} s of '{excitation.name}')"
                )
            continue
        lost_in_a_row = 0
        statusword, position, _ = struct.unpack("<Hib", link.rx1[link.sync_index])
        velocity = struct.unpack_from("<i", link.rx2[link.sync_index])[0]
        violation = setup.envelope.violation(
            position_rad=position / sc.counts_per_rad,
            velocity_rad_s=velocity / sc.velocity_units_per_rad_s,
            time_s=k * period_s,
            excitation=excitation.name,
        )
        if violation is not None:
            raise violation
        if statusword & SW_FAULT or link.emcy:
            raise _FaultedError(k * period_s)
        if statusword & 0x6F != 0x27:
            if statusword & SW_INTERNAL_LIMIT:
                raise LimitViolationError(
                    f"excitation '{excitation.name}': node {setup.node_id} stopped at its own "
                    f"limit (0x607D/0x6080, statusword bit 11) at t = {k * period_s:.3f} s"
                )
            raise DriveStateError(
                f"node {setup.node_id} left OPERATION ENABLED ({state_of(statusword)}) at "
                f"t = {k * period_s:.3f} s of '{excitation.name}'"
            )
    return done


SYNC_PRODUCER_TEXT = {
    "host": "host (python-can messages timed by the host's sleeps)",
    "periodic": "python-can's periodic send (the kernel's broadcast manager on socketcan, "
                "else python-can's own thread), times as the interface stamped the frames",
    "node": "the drive (CiA 301 0x1005 bit 30, at its 0x1006), times as the interface "
            "stamped the frames",
}


def sync_spread_s(sent_s: list[float], period_s: float) -> tuple[float, float] | None:
    """The standard deviation and the largest error of the intervals between SYNCs (s);
    ``None`` for fewer than three."""
    if len(sent_s) < 3:
        return None
    error = np.diff(np.asarray(sent_s, dtype=np.float64)) - period_s
    return float(np.std(error)), float(np.max(np.abs(error)))


def sync_timing(sent_s: list[float], period_s: float, *, realtime: bool,
                producer: str = "host") -> dict[str, str]:
    """Who produced the SYNCs and, paced by the wall clock, how evenly: the standard
    deviation and the largest error of the intervals between them. The recording's time
    base is the SYNC count (``k · period``), so this spread is error in its time axis."""
    if not realtime:
        return {"sync_producer": "host, in lockstep with the drive's answers (a simulated "
                                 "drive's clock: no wall-clock spread)"}
    timing = {"sync_producer": SYNC_PRODUCER_TEXT[producer]}
    spread = sync_spread_s(sent_s, period_s)
    if spread is not None:
        timing["sync_interval_sd_s"] = f"{spread[0]:.3g}"
        timing["sync_interval_max_error_s"] = f"{spread[1]:.3g}"
    return timing


def _stream_recording(
    link: CanLink,
    setup: RunSetup,
    excitation: Excitation,
    raw: np.ndarray,
    first: int,
    done: int,
) -> Recording:
    sc = setup.scaling
    rows = [k for k in range(done) if first + k in link.rx1 and first + k in link.rx2]
    one, two = link.decode([first + k for k in rows])
    k_arr = np.asarray(rows, dtype=np.int64)
    pos = np.asarray([r[1] for r in one], dtype=np.float64)
    vel = np.asarray([r[0] for r in two], dtype=np.float64)
    torque = np.asarray([r[1] for r in two], dtype=np.float64)
    current = np.asarray([r[2] for r in two], dtype=np.float64)
    period = 1.0 / excitation.fs_hz  # the SYNC period of this run (written by drive.run)
    mean = setup.torque_sample == "mean"
    torque_per_rated = setup.torque_per_rated
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
        # control periods of the SYNC period before SYNC k (torque_mean); the targets are
        # interpolated as stated
        "torque_sample": setup.torque_sample,
        "command_interpolation": setup.command_interpolation,
    }
    if mean:
        timing["torque_mean_period_s"] = f"{period:g}"
    if setup.control_period_s is not None:
        timing["control_period_s"] = f"{setup.control_period_s:g}"
    metadata = _metadata(
        setup,
        excitation,
        acquisition="sync stream",
        sync_period_s=f"{period:g}",
        **sync_timing(link.sync_sent_s, period, realtime=link.station.sync_pacing == "realtime",
                      producer=link.station.sync_producer),
        lost_samples=str(done - len(rows)),
        **timing,
    )
    floats = {name: np.asarray(values, dtype=np.float64) for name, values in columns.items()}
    return Recording(columns=floats, metadata=metadata, source=f"canopen:{excitation.name}")


def run_recorder(link: CanLink, setup: RunSetup, excitation: Excitation, *,
                 follower: Follower | None = None) -> Acquired:
    """Play ``excitation`` from the drive's waveform table and upload its trace recorder.

    With ``follower`` (the excitation has an ``elevation_path_rad``) the elevation's drive
    plays that path from its own table, both tables started before the same SYNC (the
    host's: nothing else produces one between the two starts), so sample k of both
    recorders is the same control period; its recorded position is the recording's
    ``elevation_rad`` column.

    Parameters
    ----------
    link : CanLink
        The node's link, the drive enabled in the excitation's mode.
    setup : RunSetup
        What acquisition needs of the drive (``recorder_rate_hz`` > 0).
    excitation : Excitation
        The command, at the recorder's rate divided by a whole number.

    Returns
    -------
    Acquired
        The uploaded samples (timed ``k / fs`` by the drive's loop), and the error that
        cut the run short, if any.

    Raises
    ------
    DriveStateError
        The excitation does not fit the recorder (nothing moved).
    """
    st_period_s = setup.sync_period_s
    recorder, waveform = setup.recorder_index, setup.waveform_index
    assert recorder is not None
    assert waveform is not None
    # the planner's own question (DriveInfo.recorder), asked again of the drive's length now
    refused = Recorder(stream_rate_hz=0.0, samples=int(link.read(recorder, 5))).refuses(
        excitation)
    if refused is not None:
        raise DriveStateError(f"{refused}: stream it (at the SYNC rate)")
    divider = round(setup.recorder_rate_hz / excitation.fs_hz)
    wave = np.repeat(_raw_command(setup, excitation), divider).astype("<i4")
    link.write(waveform, 1, wave.tobytes())
    link.write(recorder, 3, divider)
    if follower is not None:
        assert excitation.elevation_path_rad is not None
        follower.play(excitation.elevation_path_rad, divider=divider)
    link.write(recorder, 1, 1)
    loop_s = 1.0 / setup.recorder_rate_hz
    ticks = math.ceil(len(wave) * loop_s / st_period_s) + 1
    error: DriveError | None = None
    try:
        for tick in range(ticks):
            link.tick()
            status = link.latest_status()
            if status is not None and status[0] & SW_INTERNAL_LIMIT and status[0] & 0x6F != 0x27:
                raise LimitViolationError(
                    f"excitation '{excitation.name}': node {setup.node_id} stopped at its own "
                    f"limit (0x607D/0x6080, statusword bit 11) at t = {tick * st_period_s:.3f} s "
                    "(drive recorder)"
                )
            if status is not None and (status[0] & SW_FAULT or link.emcy):
                raise DriveFaultError(
                    f"node {setup.node_id} faulted at t = {tick * st_period_s:.3f} s of "
                    f"'{excitation.name}' (EMCY, drive recorder)",
                    code=(link.emcy[-1][0] if link.emcy else 0) or link.fault_code(),
                )
        if int(link.read(recorder, 2)) != 2:
            raise DriveStateError(f"drive recorder did not finish '{excitation.name}'")
        # the stream's held target takes over from the table: where the run ended (a stale
        # one pulled the azimuth back from 1.89 rad while a held elevation moved, and the
        # drive stopped at its own limit)
        _hold_where_it_ended(link, excitation.mode, wave)
    except DriveError as exc:
        error = exc
    # a stop signal propagates: the caller quick-stops first, then uploads (recorder_upload)
    recording = recorder_upload(link, setup, excitation, divider)
    if follower is None or error is not None:
        return Acquired(recording, error)
    try:
        followed = follower.played_rad()
    except DriveError as exc:
        return Acquired(recording, exc)
    if len(followed) != len(recording):
        return Acquired(recording, DriveStateError(
            f"'{excitation.name}': the elevation's recorder holds {len(followed)} samples, "
            f"node {setup.node_id}'s {len(recording)}: not one run"))
    return Acquired(replace(recording, columns={**recording.columns,
                                                "elevation_rad": followed}))


def recorder_upload(link: CanLink, setup: RunSetup, excitation: Excitation,
                    divider: int) -> Recording:
    """What the drive recorder holds of ``excitation`` (all of it after a finished run,
    the samples up to the stop after an interrupted one), uploaded by segmented SDO."""
    sc = setup.scaling
    recorder = setup.recorder_index
    data = bytes(link.read(recorder, 7)) if link.connected and recorder is not None else b""
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
    return Recording(
        columns=columns,
        metadata=_metadata(
            setup,
            excitation,
            acquisition="drive recorder",
            recorder_divider=str(divider),
            control_period_s=f"{1.0 / setup.recorder_rate_hz:g}",
            torque_sample="instantaneous",
            command_interpolation="hold",  # the waveform table repeats each command sample
        ),
        source=f"canopen-recorder:{excitation.name}",
    )
