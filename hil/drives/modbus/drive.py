"""ModbusDrive: the Drive contract over Modbus TCP or RTU (pymodbus), by polling.

Cut as the CANopen backend is: the link (``link.py``: client, resend, exception codes,
register values), the acquisition (``acquire.py``: feedback block, polled run, timing by
the drive's clock, averaged torque, rate check), the state machine (``state_machine.py``:
enable with fault reset, mode selection, disable, quick stop) and, here, their composition
and the connection-time facts:
``info.max_sample_rate_hz`` is measured at connection (70 % of the typical rate of a
write and a read: the median poll, so one stall of an overloaded host does not set it;
rounded down to 1-2-5) and capped by the station's ``max_poll_rate_hz``. It is a snapshot:
a run that achieves less than ``MIN_RATE_FRACTION`` of its requested rate raises
:class:`DriveCommunicationError` (partial recording attached) instead of returning a
recording with the excitation's timing gone. Torque: with ``torque_mean`` in the map (and
the station's ``torque_sample`` not ``"instantaneous"``) each row's torque is the drive's
mean of the torque commanded per control period since the previous feedback read; its
length (``torque_mean_window``, if the map has it) goes into a ``torque_mean_window_s``
column.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from hil.drives.base import (
    Capability,
    Drive,
    DriveInfo,
    DriveState,
    DriveStatus,
    MotionEnvelope,
    Recorder,
    check_limits,
    interrupted,
)
from hil.drives.equipment import Equipment, sensor_fields
from hil.drives.held import HeldAxes
from hil.drives.locked import ClampedRotor
from hil.drives.modbus.acquire import (
    Feedback,
    PolledRun,
    poll,
    rate_shortfall,
    set_interpolation,
    setpoint_holds,
    to_recording,
)
from hil.drives.modbus.held_axis import KEEPALIVE_S, HeldModbusAxis
from hil.drives.modbus.link import ModbusLink
from hil.drives.modbus.recorder import (
    play,
    plays_torque_offset,
    recorder_capacity,
    recorder_rate_hz,
    recorder_refusal,
    upload,
)
from hil.drives.modbus.regmap import (
    COMPENSATION,
    DIGITAL_OUTPUTS,
    TORQUE_MEAN,
    TORQUE_OFFSET,
    RegisterMap,
    load_register_map,
)
from hil.drives.modbus.state_machine import ModbusStateMachine
from hil.drives.realtime import collector_held
from hil.drives.station import ModbusStation
from hil.errors import (
    DriveCommunicationError,
    DriveError,
    DriveStateError,
    LimitViolationError,
    ProfileError,
)
from hil.motion import CompensationTable, Excitation, Limits, Mode, PositionHarmonic
from hil.recording import Recording

log = logging.getLogger(__name__)


def nice_rate(rate_hz: float) -> float:
    """Largest 1-2-5 value not above ``rate_hz``."""
    decade = 10.0 ** math.floor(math.log10(rate_hz))
    for step in (5.0, 2.0, 1.0):
        if step * decade <= rate_hz:
            return step * decade
    return decade  # pragma: no cover


class ModbusDrive(ClampedRotor, Drive):
    """A drive on Modbus TCP or RTU, described by a register map.

    Parameters
    ----------
    station : ModbusStation
        Transport, address, unit id, timeouts, register map, poll-rate cap.
    limits : Limits
        The unit's envelope, refused before motion.

    Raises
    ------
    ProfileError
        The register map cannot be used (or lacks ``torque_mean`` the station requires).
    DriveCommunicationError
        The drive cannot be reached.
    """

    def __init__(self, station: ModbusStation, *, limits: Limits) -> None:
        self.station = station
        self.limits = limits
        self.map: RegisterMap = load_register_map(station.register_map_path)
        self.torque_sample = self._choose_torque_sample()
        self.link = ModbusLink(station, self.map)
        self.feedback = Feedback(self.link, self.torque_sample)  # checks the map: no I/O
        self.states = ModbusStateMachine(self.link, self.feedback)
        self.link.connect()
        self.held: HeldAxes[HeldModbusAxis] = HeldAxes()  # the gimbal's other axes here
        self.poll_rate_hz = 0.0  # measured at connection (info.max_sample_rate_hz unless
        self.recorder_rate_hz = 0.0  # the drive recorder, at its control rate, is faster)
        self._idle = threading.Event()  # set: the held axes' idle keepalive ends
        try:
            self._info = self._read_info()
            for name, unit_id in station.held.items():
                axis = HeldModbusAxis(self.link, name=name, unit_id=unit_id,
                                      hold=station.gimbal.hold,
                                      others=self._keepalive_all_but(name))
                self.held.axes[name] = axis
                axis.enable()
                if name in station.gimbal.hold.at_rad:
                    axis.move_to(station.gimbal.hold.at_rad[name])
            if self.held.axes or self._info.recorder is not None:
                threading.Thread(target=self._keep_idle_drives, name="modbus-idle-keepalive",
                                 daemon=True).start()
        except BaseException:
            self.held.release()
            self.link.close()
            raise

    def _choose_torque_sample(self) -> str:
        """``"mean"`` when the map declares ``torque_mean`` and the station does not say
        ``"instantaneous"``; ``"mean"`` in the station requires it."""
        wanted = self.station.torque_sample
        if wanted == "instantaneous":
            return "instantaneous"
        if TORQUE_MEAN in self.map.registers:
            return "mean"
        if wanted == "mean":
            raise ProfileError(
                f"torque_sample = 'mean' but the register map {self.map.source} has no "
                f"'{TORQUE_MEAN}' register",
                source=self.station.source,
            )
        return "instantaneous"

    def read_values(self, names: tuple[str, ...]) -> dict[str, float]:
        """Read registers by name, in SI units (see :meth:`ModbusLink.read_values`)."""
        return self.link.read_values(names)

    def write_value(self, name: str, value_si: float) -> None:
        """Write one register from an SI value (see :meth:`ModbusLink.write_value`)."""
        self.link.write_value(name, value_si)

    # -- info ----------------------------------------------------------------------------
    def _read_info(self) -> DriveInfo:
        ident = self.read_values(("firmware_version", "serial_number", "rated_torque"))
        firmware = int(ident.get("firmware_version", 0))
        rate = self.poll_rate_hz = self._measure_poll_rate()
        recorder = None
        if self.station.acquisition != "stream" and (
                recorder_rate := recorder_rate_hz(self.link)) > rate:
            recorder = Recorder(stream_rate_hz=rate, samples=recorder_capacity(self.link),
                                torque_offset=plays_torque_offset(self.link))
            self.recorder_rate_hz = recorder_rate
        return DriveInfo(
            vendor="modbus",
            model=self.map.model,
            firmware_version=f"{firmware >> 8}.{firmware & 0xFF}",
            serial=str(int(ident.get("serial_number", 0))),
            rated_torque_nm=float(ident.get("rated_torque", self.limits.torque_nm)),
            limits=self.limits,
            modes=tuple(
                Mode(name) for name in self.map.modes if name in ("torque", "velocity", "position")
            ),
            max_sample_rate_hz=max(rate, self.recorder_rate_hz),
            recorder=recorder,
            capabilities=self._clamp_equipment().capabilities() | frozenset(
                {Capability.ELEVATION_AXIS} if "elevation" in self.station.held else ()
            ) | frozenset({Capability.COMPENSATION_TABLE} if self.map.has_compensation else ()),
            **sensor_fields(self._clamp_equipment()),
            transport=self.link.where,
        )

    def _measure_poll_rate(self, polls: int = 30) -> float:
        """A sample costs a command write and a feedback read; a read is timed (it moves
        nothing) and the write taken to cost as much. The median read, not the mean: one
        stall of an overloaded host (0.2-1 s seen) would otherwise set the rate of the
        whole session (seen: 20 Hz chosen where 100 Hz were sustained)."""
        reads = []
        for _ in range(polls):
            start = time.monotonic()
            self.feedback.read()
            reads.append(time.monotonic() - start)
        per_sample = 2 * float(np.median(reads))
        achievable = 0.7 / max(per_sample, 1e-6)
        return nice_rate(min(self.station.max_poll_rate_hz, achievable))

    @property
    def info(self) -> DriveInfo:
        """What the drive is and can do (read and measured at connection)."""
        return self._info

    # -- state ---------------------------------------------------------------------------
    def status(self) -> DriveStatus:
        """The drive's state, position and velocity (one feedback read)."""
        return self.states.status()

    def enable(self, mode: Mode = Mode.VELOCITY) -> None:
        """Reset a fault, select ``mode`` holding the axis, and enable, each confirmed.

        Parameters
        ----------
        mode : Mode
            The excitation mode the next runs use (a run in another mode switches).

        Raises
        ------
        DriveFaultError
            The drive is in fault after enabling.
        DriveStateError
            The reset, the mode or the enable was not confirmed.
        """
        self.states.enable(mode)

    def disable(self) -> None:
        """Clear the control word, confirmed; idempotent, and logs what it cannot do."""
        self.states.disable()

    def quick_stop(self) -> None:
        """Quick stop by the drive's ramp, confirmed at rest (reconnecting if needed)."""
        self.states.quick_stop()

    def set_elevation(self, elevation_rad: float) -> None:
        """Move the gimbal's elevation axis (a held unit on this link) to ``elevation_rad``
        and hold it there.

        Raises
        ------
        DriveStateError
            The station holds no elevation axis, or it did not reach the angle in time.
        """
        if not self.held.move("elevation", elevation_rad):
            super().set_elevation(elevation_rad)

    def _keepalive(self) -> None:
        for axis in self.held.axes.values():
            axis.keepalive()

    def _keep_idle_drives(self) -> None:
        """Between runs the host analyses what it recorded (a 4 kHz recording's analysis
        takes longer than a watchdog time: the azimuth tripped 0x8130 after the J/B/T_c
        sines, every time, once their runs went to the recorder), so a status read goes to
        each drive on the link, the axis under test's and the held axes', silent for
        2 × :data:`KEEPALIVE_S`, from its own thread (the link serialises requests). A host
        that dies takes the thread with it and the drives' watchdogs stop the axes. Faults
        are found by the next run or enable, not here."""
        links = [self.link, *(axis.link for axis in self.held.axes.values())]
        while not self._idle.wait(KEEPALIVE_S / 2):
            for link in links:
                if time.monotonic() - link.last_request_s < 2 * KEEPALIVE_S:
                    continue
                try:
                    link.read_values(("status_word",))
                except DriveError as exc:
                    log.debug("%s: idle keepalive: %s", link.where, exc)

    def _keepalive_all_but(self, moving: str) -> Callable[[], None]:
        """While the held axis ``moving`` moves: a request to this drive and to every other
        held axis at least every :data:`KEEPALIVE_S` (their watchdogs)."""
        last = [time.monotonic()]

        def keepalive() -> None:
            if time.monotonic() - last[0] >= KEEPALIVE_S:
                last[0] = time.monotonic()
                self.link.read_values(("status_word",))
            for name, axis in self.held.axes.items():
                if name != moving:
                    axis.keepalive()

        return keepalive

    def close(self) -> None:
        """Disable (the held axes first), then close the connection."""
        try:
            self._idle.set()
            self._close_transducer()
            self.held.release()
            self.disable()
        finally:
            self.link.close()

    # -- run -----------------------------------------------------------------------------
    def run(self, excitation: Excitation) -> Recording:
        """Poll ``excitation``: each command sample written at its time, the feedback read
        half a period later, rows timed by the drive's clock if the map has one. See
        :meth:`Drive.run`.

        Raises
        ------
        DriveStateError
            The drive is not enabled or the rate exceeds ``info.max_sample_rate_hz``;
            nothing moved.
        LimitViolationError
            The command leaves the unit's limits; nothing moved.
        DriveError
            A fault, a lost link, or a run below ``MIN_RATE_FRACTION`` of its rate: the
            drive made safe, the partial recording attached. A
            :class:`LimitViolationError` when the measured motion left the monitor's
            :class:`MotionEnvelope` (the register map has no limits of its own: the
            host's monitor quick-stops the drive).
        """
        states = self.states
        if states.state is not DriveState.ENABLED:
            raise DriveStateError(f"cannot run '{excitation.name}': drive is {states.state.value}")
        if self.recorder_rate_hz and excitation.fs_hz > self.poll_rate_hz * (1 + 1e-9):
            return self._run_recorder(excitation)
        if excitation.fs_hz > self.poll_rate_hz * (1 + 1e-9):
            raise DriveStateError(
                f"excitation '{excitation.name}' is sampled at {excitation.fs_hz} Hz; this "
                f"Modbus link polls at up to {self.poll_rate_hz:g} Hz"
            )
        start = self.status()
        check_limits(excitation, self.limits, start_position_rad=start.position_rad)
        if excitation.torque_offset_nm is not None and TORQUE_OFFSET not in self.map.registers:
            raise DriveStateError(f"excitation '{excitation.name}' sends a torque offset; the "
                                  f"register map has no '{TORQUE_OFFSET}' register")
        if excitation.mode is not states.mode:
            states.select(excitation.mode)
        set_interpolation(self.link, self.link.station.setpoint_lead_periods / excitation.fs_hz)
        run = PolledRun()
        shaft, keepalive = self._shaft, self._keepalive
        if shaft is not None:  # read once per row, in the time the row leaves
            started = time.monotonic()  # the rows' time base starts here too
            shaft.begin(lambda: time.monotonic() - started)

            def keepalive() -> None:
                self._keepalive()
                shaft.read_in_step()
        error: DriveError | None = None
        log.info("%s: polling %s (%.2f s at %g Hz)", self.link.where, excitation.name,
                 excitation.duration_s, excitation.fs_hz)
        try:
            with collector_held():
                try:
                    poll(excitation, run, self.feedback, MotionEnvelope.of(self.limits),
                         keepalive=keepalive)
                except LimitViolationError:  # the axis runs away: stop it before all else
                    states.send_quick_stop()
                    raise
        except DriveError as exc:
            error = exc
        except KeyboardInterrupt as stop:  # a stop signal: quick stop, keep the rows so far
            states.quick_stop()
            raise interrupted(stop, to_recording(excitation, run, self.feedback,
                                                 self._info)) from stop
        except BaseException:
            states.quick_stop()
            raise
        recording = to_recording(excitation, run, self.feedback, self._info)
        if self.held.axes and not isinstance(error, DriveCommunicationError):
            recording = replace(recording, metadata={**recording.metadata,
                                                     "held_axes": self.held.text()})
        if error is None:
            error = rate_shortfall(excitation, run, self.link) or setpoint_holds(
                excitation, run, self.link.station, self.link.where)
            if error is not None:
                states.hold(excitation.mode)
        if error is not None:
            states.make_safe(error)
            error.partial_recording = recording
            raise error
        states.hold(excitation.mode)
        if shaft is not None:
            return shaft.on_rows(recording)
        return recording

    def _run_recorder(self, excitation: Excitation) -> Recording:
        """Play ``excitation`` on the drive recorder (see :mod:`hil.drives.modbus.recorder`):
        a stop signal or an error while it plays quick-stops and disables the drive, and
        what it captured until then is read back and kept."""
        states, fs = self.states, excitation.fs_hz
        if self._shaft is not None:
            raise DriveStateError(
                f"excitation '{excitation.name}' at {fs:g} Hz would run on the drive "
                "recorder, which does not record the station's torque transducer: poll it "
                f"(at most {self.poll_rate_hz:g} Hz)")
        assert self._info.recorder is not None  # a recorder rate is set only with one
        refused = recorder_refusal(excitation, rate_hz=self.recorder_rate_hz,
                                   capacity=self._info.recorder.samples,
                                   torque_offset=self._info.recorder.torque_offset)
        if refused is not None:
            raise DriveStateError(f"{refused}: poll it (at most {self.poll_rate_hz:g} Hz)")
        start = self.status()
        check_limits(excitation, self.limits, start_position_rad=start.position_rad)
        if excitation.mode is not states.mode:
            states.select(excitation.mode)
        divider = round(self.recorder_rate_hz / fs)
        error: DriveError | None = None
        try:
            with collector_held():
                play(self.link, self.feedback, excitation, rate_hz=self.recorder_rate_hz,
                     divider=divider, envelope=MotionEnvelope.of(self.limits),
                     keepalive=self._keepalive, torque_mean=self.torque_sample == "mean")
        except DriveError as exc:
            error = exc
        except KeyboardInterrupt as stop:  # a stop signal: stop, then keep what it captured
            states.quick_stop()
            states.disable()
            raise interrupted(stop, self._recorded(excitation, divider)) from stop
        except BaseException:
            states.quick_stop()
            states.disable()
            raise
        if error is not None:
            states.make_safe(error)
            error.partial_recording = self._recorded(excitation, divider)
            raise error
        recording = upload(self.link, excitation, self._info, rate_hz=self.recorder_rate_hz,
                           divider=divider, keepalive=self._keepalive,
                           torque_mean=self.torque_sample == "mean")
        if self.held.axes:
            recording = replace(recording, metadata={**recording.metadata,
                                                     "held_axes": self.held.text()})
        return recording

    def _recorded(self, excitation: Excitation, divider: int) -> Recording | None:
        """After a stopped or failed play (the drive made safe): what the recorder
        captured, or ``None`` when it cannot be read (logged)."""
        def keepalive() -> None:  # the held axes' watchdogs; their faults are not this one's
            try:
                self._keepalive()
            except DriveError as exc:
                log.warning("%s", exc)

        try:
            return upload(self.link, excitation, self._info, rate_hz=self.recorder_rate_hz,
                          divider=divider, keepalive=keepalive,
                          torque_mean=self.torque_sample == "mean")
        except DriveError as exc:
            log.warning("%s: the drive recorder's samples of '%s' not read: %s",
                        self.link.where, excitation.name, exc)
            return None

    def load_compensation(self, table: CompensationTable | None) -> None:
        """Write a cogging compensation table into the map's compensation registers
        (``None``: every slot cleared), all of them in one request.

        Raises
        ------
        DriveStateError
            The register map has no compensation table, or the table has more harmonics
            than its slots.
        """
        if not self.map.has_compensation:
            raise self._without(Capability.COMPENSATION_TABLE)
        start, count = self.map.compensation_span()
        words = [0] * count
        tables: dict[str, tuple[PositionHarmonic, ...]] = {
            "cogging": () if table is None else table.cogging_nm,
            "kt_ripple": () if table is None else table.kt_ripple}
        for kind, harmonics in tables.items():
            names = COMPENSATION[kind]
            slots = self.map[names[0]].length
            if len(harmonics) > slots:
                raise DriveStateError(
                    f"{self.link.where}: the compensation table has {len(harmonics)} {kind} "
                    f"harmonics; the register map {self.map.source} holds {slots}")
            columns: tuple[list[float], ...] = (
                [float(h.order) for h in harmonics], [h.amplitude for h in harmonics],
                [h.phase_rad for h in harmonics])
            for name, values in zip(names, columns, strict=True):
                register = self.map[name]
                raw = np.zeros(register.length)
                raw[: len(values)] = np.asarray(values, dtype=np.float64) / register.scale
                at = register.address - start
                words[at : at + register.words] = register.encode_raw(raw)
        self.link.write_words(start, words, "compensation table")

    def _clamp_equipment(self) -> Equipment:
        """The station's equipment the register map can serve (a clamp needs the map's
        digital outputs)."""
        equipment = self.station.equipment
        if equipment.locked_rotor is not None and DIGITAL_OUTPUTS not in self.map.registers:
            return Equipment(torque_transducer=equipment.torque_transducer)
        return equipment

    def _check_rate_hz(self) -> float:
        return self.poll_rate_hz

    def _set_clamp(self, engaged: bool) -> None:
        fixture = self.station.equipment.locked_rotor
        assert fixture is not None
        self.link.write_value(DIGITAL_OUTPUTS, float(1 << fixture.output_bit if engaged else 0))
