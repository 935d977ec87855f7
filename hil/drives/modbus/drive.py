"""ModbusDrive: the Drive contract over Modbus TCP or RTU (pymodbus), by polling.

Sample ``k`` of a run: the command sample ``k`` is written at ``k/fs`` and the feedback
block read half a period later (away from the loop's response to the new setpoint).
Timing: if the register map has a ``timestamp`` register (the drive's free-running clock,
latched with the feedback and read in the same request) the recording's ``time_s`` is that
clock, unwrapped; otherwise it is the host's monotonic clock at the middle of the read
transaction, which carries the link's jitter. If the map has a
``setpoint_interpolation_time`` register it is set to the sample period, so the drive
ramps between setpoints instead of stepping. ``metadata["acquisition"]`` says which.
``info.max_sample_rate_hz`` is measured at connection (70 % of the typical rate of a
write and a read: the median poll, so one stall of an overloaded host does not set it;
rounded down to 1-2-5) and capped by the station's ``max_poll_rate_hz``. It is a snapshot:
a run that achieves less than ``MIN_RATE_FRACTION`` of its requested rate raises
:class:`DriveCommunicationError` (partial recording attached) instead of returning a
recording with the excitation's timing gone. Torque: with ``torque_mean`` in the map (and
the station's ``torque_sample`` not ``"instantaneous"``) each row's torque is the drive's
mean of the torque commanded per control period since the previous feedback read, i.e.
over the control periods after the previous row's latched sample up to its own; its length
(``torque_mean_window``, if the map has it) goes into a ``torque_mean_window_s`` column.
Over TCP a request that timed out is sent once
more (same transaction id, so a late first answer is matched and a stale one skipped).
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any

import numpy as np

from hil.drives.base import Drive, DriveInfo, DriveState, DriveStatus, check_limits
from hil.drives.modbus.link import ModbusLink
from hil.drives.modbus.regmap import (
    FEEDBACK,
    SETPOINT_INTERPOLATION,
    TIMESTAMP,
    TORQUE_MEAN,
    TORQUE_MEAN_WINDOW,
    RegisterMap,
    load_register_map,
)
from hil.drives.station import ModbusStation
from hil.errors import (
    DriveCommunicationError,
    DriveError,
    DriveFaultError,
    DriveStateError,
    ProfileError,
)
from hil.motion import COMMAND_COLUMN, Excitation, Limits, Mode
from hil.recording import Recording

log = logging.getLogger(__name__)

MIN_RATE_FRACTION = 0.7  # of the requested sample rate a run must achieve
WATCHDOG_FAULT = 0x8130  # CiA-style life guard / heartbeat error: the drive lost its master


def nice_rate(rate_hz: float) -> float:
    """Largest 1-2-5 value not above ``rate_hz``."""
    decade = 10.0 ** math.floor(math.log10(rate_hz))
    for step in (5.0, 2.0, 1.0):
        if step * decade <= rate_hz:
            return step * decade
    return decade  # pragma: no cover


class ModbusDrive(Drive):
    def __init__(self, station: ModbusStation, *, limits: Limits) -> None:
        self.station = station
        self.limits = limits
        self.map: RegisterMap = load_register_map(station.register_map_path)
        self._state = DriveState.DISABLED
        self._longest_pause_s = 0.0  # between two feedback polls of the last run
        self._has_timestamp = TIMESTAMP in self.map.registers
        self.torque_sample = self._choose_torque_sample()
        mean = self.torque_sample == "mean"
        latched = tuple(
            name
            for name in (TORQUE_MEAN, TORQUE_MEAN_WINDOW)
            if mean and name in self.map.registers
        ) + ((TIMESTAMP,) if self._has_timestamp else ())
        self._feedback_names = FEEDBACK + latched
        self._blocks = self.map.blocks(self._feedback_names)
        if latched and len(self._blocks) > 1:
            names = ", ".join(f"'{name}'" for name in latched)
            raise ProfileError(
                f"register{'s' if len(latched) > 1 else ''} {names} must be read in one "
                f"request with the feedback ({', '.join(FEEDBACK)}); they span "
                f"{len(self._blocks)} reads of at most {self.map.max_registers_per_read} "
                "registers",
                source=self.map.source,
            )
        self.link = ModbusLink(station, self.map)
        try:
            self._info = self._read_info()
        except BaseException:
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
        rate = self._measure_poll_rate()
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
            max_sample_rate_hz=rate,
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
            self._feedback()
            reads.append(time.monotonic() - start)
        per_sample = 2 * float(np.median(reads))
        achievable = 0.7 / max(per_sample, 1e-6)
        return nice_rate(min(self.station.max_poll_rate_hz, achievable))

    @property
    def info(self) -> DriveInfo:
        return self._info

    # -- state ---------------------------------------------------------------------------
    def _feedback(self) -> tuple[float, dict[str, float]]:
        """One poll of the feedback block: (host time at the middle, values)."""
        t0 = time.monotonic()
        words = self.link.read_words(self._blocks)
        t1 = time.monotonic()
        return (t0 + t1) / 2, self.link.decode(words, self._feedback_names)

    def _bit(self, values: dict[str, float], name: str) -> bool:
        return bool(int(values["status_word"]) >> self.map.status_bits[name] & 1)

    def status(self) -> DriveStatus:
        _, v = self._feedback()
        fault = self._bit(v, "fault")
        state = (
            DriveState.FAULT
            if fault
            else (
                DriveState.QUICK_STOPPED
                if self._bit(v, "quick_stop_active")
                else DriveState.ENABLED
                if self._bit(v, "enabled")
                else DriveState.DISABLED
            )
        )
        return DriveStatus(
            state=state,
            position_rad=v["position"],
            velocity_rad_s=v["velocity"],
            fault_code=int(v["fault_code"]) if fault else None,
        )

    def _control(self, *bits: str) -> None:
        word = sum(1 << self.map.control_bits[b] for b in bits)
        self.write_value("control_word", word)

    def _await(self, what: str, done: Any, timeout_s: float = 2.0) -> dict[str, float]:
        deadline = time.monotonic() + timeout_s
        while True:
            _, values = self._feedback()
            if done(values):
                return values
            if time.monotonic() > deadline:
                raise DriveStateError(
                    f"{self.link.where}: {what} not confirmed "
                    f"(status word 0x{int(values['status_word']):04X})"
                )
            time.sleep(0.005)

    def enable(self, mode: Mode = Mode.VELOCITY) -> None:
        _, values = self._feedback()
        if self._bit(values, "fault"):
            code = int(values["fault_code"])
            self._control("fault_reset")
            self._control()
            values = self._await("fault reset", lambda v: not self._bit(v, "fault"))
            log.info("%s: fault 0x%04X reset", self.link.where, code)
        self._select(mode)
        self._control("enable")
        self._await("enable", lambda v: self._bit(v, "enabled") or self._bit(v, "fault"))
        self._raise_if_faulted("while enabling")
        self._state = DriveState.ENABLED

    def _select(self, mode: Mode) -> None:
        self.write_value(f"{mode.value}_cmd", self._hold_value(mode))
        self.write_value("mode", self.map.modes[mode.value])
        if int(self.read_values(("mode",))["mode"]) != self.map.modes[mode.value]:
            raise DriveStateError(f"{self.link.where}: mode register does not show {mode.value}")
        self._mode = mode

    def _hold_value(self, mode: Mode) -> float:
        if mode is Mode.POSITION:
            return self.read_values(("position",))["position"]
        return 0.0

    def _raise_if_faulted(self, context: str) -> None:
        _, values = self._feedback()
        if self._bit(values, "fault"):
            self._state = DriveState.FAULT
            raise DriveFaultError(
                f"{self.link.where}: drive fault {context}", code=int(values["fault_code"])
            )

    def disable(self) -> None:
        if not self.link.connected:
            self._state = DriveState.DISABLED
            return
        try:
            self._control()
            self._await("disable", lambda v: not self._bit(v, "enabled"))
        except DriveError as exc:
            log.error("%s: disable not confirmed: %s", self.link.where, exc)
        self._state = DriveState.DISABLED

    def quick_stop(self) -> None:
        try:
            if not self.link.connected:
                self.link.connect()  # the drive's watchdog stops it anyway; try to confirm
            self._control("quick_stop")
            self._await(
                "quick stop",
                lambda v: not self._bit(v, "enabled") and abs(v["velocity"]) < 1e-2,
                timeout_s=5.0,
            )
        except DriveError as exc:
            log.error("%s: quick stop not confirmed: %s", self.link.where, exc)
        self._state = DriveState.QUICK_STOPPED

    def close(self) -> None:
        try:
            self.disable()
        finally:
            self.link.close()

    # -- run -----------------------------------------------------------------------------
    def run(self, excitation: Excitation) -> Recording:
        if self._state is not DriveState.ENABLED:
            raise DriveStateError(f"cannot run '{excitation.name}': drive is {self._state.value}")
        if excitation.fs_hz > self._info.max_sample_rate_hz * (1 + 1e-9):
            raise DriveStateError(
                f"excitation '{excitation.name}' is sampled at {excitation.fs_hz} Hz; this "
                f"Modbus link polls at up to {self._info.max_sample_rate_hz:g} Hz"
            )
        start = self.status()
        check_limits(excitation, self.limits, start_position_rad=start.position_rad)
        if excitation.mode is not getattr(self, "_mode", None):
            self._select(excitation.mode)
        self._set_interpolation(1.0 / excitation.fs_hz)
        rows: list[tuple[float, float, dict[str, float]]] = []
        error: DriveError | None = None
        try:
            self._poll(excitation, rows)
        except DriveError as exc:
            error = exc
        except BaseException:
            self.quick_stop()
            raise
        recording = self._recording(excitation, rows)
        if error is None:
            error = self._rate_shortfall(excitation, len(rows))
            if error is not None:
                self.write_value(f"{excitation.mode.value}_cmd", self._hold_value(excitation.mode))
        if error is not None:
            if isinstance(error, DriveFaultError):
                self._state = DriveState.FAULT
            self.quick_stop()
            self.disable()
            error.partial_recording = recording
            raise error
        self.write_value(f"{excitation.mode.value}_cmd", self._hold_value(excitation.mode))
        return recording

    def _rate_shortfall(self, excitation: Excitation, polls: int) -> DriveError | None:
        """The run achieved too few samples for its timing to mean what the protocol
        planned (the connection-time rate is a snapshot; the machine's load may have risen)."""
        achieved = polls / max(excitation.duration_s, 1e-9)
        if achieved >= MIN_RATE_FRACTION * excitation.fs_hz:
            return None
        return DriveCommunicationError(
            f"{self.link.where}: '{excitation.name}' polled at {achieved:.0f} Hz of the "
            f"{excitation.fs_hz:g} Hz requested (< {MIN_RATE_FRACTION:.0%}; longest pause "
            f"{self._longest_pause_s:.3f} s): the host could not keep up, the recording is "
            f"not the planned excitation; lower max_poll_rate_hz in {self.station.source} "
            f"or unload the machine"
        )

    def _set_interpolation(self, period_s: float) -> None:
        """Let the drive ramp over one sample period to each new setpoint (if it can)."""
        if SETPOINT_INTERPOLATION not in self.map.registers:
            return
        register = self.map[SETPOINT_INTERPOLATION]
        if round(period_s / register.scale) >= register.modulus:
            raise DriveStateError(
                f"{self.link.where}: sample period {period_s:g} s exceeds the range of "
                f"'{SETPOINT_INTERPOLATION}' ({(register.modulus - 1) * register.scale:g} s)"
            )
        self.write_value(SETPOINT_INTERPOLATION, period_s)

    def _poll(
        self, excitation: Excitation, rows: list[tuple[float, float, dict[str, float]]]
    ) -> None:
        command = np.asarray(excitation.command, dtype=np.float64)
        name = f"{excitation.mode.value}_cmd"
        fs, n = excitation.fs_hz, len(command)
        last_index = -1
        t0 = time.monotonic()
        self._longest_pause_s = 0.0
        previous = t0
        while True:
            index = int((time.monotonic() - t0) * fs)
            if index >= n:
                return
            if index != last_index:
                self.write_value(name, float(command[index]))
                last_index = index
            # read half a period after the setpoint changed: a drive that steps to it
            # answers with a torque transient whose start would be sampled every time
            delay = t0 + (index + 0.5) / fs - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            stamp, values = self._feedback()
            self._longest_pause_s = max(self._longest_pause_s, stamp - previous)
            previous = stamp
            rows.append((stamp - t0, float(command[index]), values))
            if self._bit(values, "fault"):
                code = int(values["fault_code"])
                why = ""
                if code == WATCHDOG_FAULT:
                    why = (
                        f": communication watchdog, the drive saw no request for its watchdog "
                        f"time (station watchdog_s = {self.station.watchdog_s:g} s); longest "
                        f"pause between our polls this run {self._longest_pause_s:.3f} s "
                        "(host overloaded or stalled?)"
                    )
                raise DriveFaultError(
                    f"{self.link.where}: drive fault at t = {stamp - t0:.3f} s of "
                    f"'{excitation.name}'{why}",
                    code=code,
                )
            if not self._bit(values, "enabled"):
                raise DriveStateError(
                    f"{self.link.where}: drive disabled itself during '{excitation.name}'"
                )
            next_due = t0 + (index + 1) / fs
            delay = next_due - time.monotonic()
            if delay > 0:
                time.sleep(delay)

    def _recording(
        self, excitation: Excitation, rows: list[tuple[float, float, dict[str, float]]]
    ) -> Recording:
        host_s = np.asarray([r[0] for r in rows], dtype=np.float64)
        duplicates = 0
        if self._has_timestamp and rows:
            time_s = self._drive_time(host_s, [r[2][TIMESTAMP] for r in rows])
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
        if SETPOINT_INTERPOLATION in self.map.registers:
            acquisition += f"; setpoint interpolated over {1.0 / excitation.fs_hz:g} s"
        else:
            acquisition += "; setpoint stepped at each write"
        mean = self.torque_sample == "mean"
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
        if "current" in self.map.registers:
            columns["current_a"] = column("current")
        timing: dict[str, str] = {}
        if mean:
            # row k's torque: the mean over the control periods after row k-1's latched
            # sample up to row k's (unless something else read the register between)
            if TORQUE_MEAN_WINDOW in self.map.registers:
                window = column(TORQUE_MEAN_WINDOW)
                columns["torque_mean_window_s"] = window
            else:
                window = np.diff(time_s)
            period = float(np.median(window)) if window.size else 1.0 / excitation.fs_hz
            timing["torque_mean_period_s"] = f"{period:g}"
        if self._has_timestamp and rows:
            timing["drive_clock_at_start_s"] = f"{rows[0][2][TIMESTAMP]:.6f}"
        metadata = {
            "drive": self.link.where,
            "unit_id": str(self.station.unit_id),
            "model": self._info.model,
            "firmware": self._info.firmware_version,
            "serial": self._info.serial,
            "transport": self._info.transport,
            "excitation": excitation.name,
            "control_mode": excitation.mode.value,
            "acquisition": acquisition,
            "poll_rate_hz": f"{len(rows) / max(excitation.duration_s, 1e-9):.1f}",
            "requested_rate_hz": f"{excitation.fs_hz:g}",
            "longest_gap_s": f"{float(np.max(np.diff(time_s), initial=0.0)):.4f}",
            "duplicate_reads_dropped": str(duplicates),
            # row k: the drive's state latched at one control period (position measured at
            # its start, torque commanded over it, or with "mean" the mean of the torque
            # commanded per control period over the row's window ending with that period),
            # as the CANopen backend states it
            "torque_sample": self.torque_sample,
            **timing,
            "command_interpolation": (
                "linear" if SETPOINT_INTERPOLATION in self.map.registers else "hold"
            ),
            **(
                {"control_period_s": f"{self.map.control_period_s:g}"}
                if self.map.control_period_s is not None
                else {}
            ),
            **excitation.metadata,
        }
        return Recording(columns=columns, metadata=metadata, source=f"modbus:{excitation.name}")

    def _drive_time(self, host_s: np.ndarray, clock_s: list[float]) -> np.ndarray:
        """The drive's wrapping clock unwrapped (each step's wrap count chosen to match the
        host's elapsed time), offset to start at the first sample's host time."""
        register = self.map[TIMESTAMP]
        wrap_s = register.modulus * register.scale
        clock = np.asarray(clock_s, dtype=np.float64)
        step = np.diff(clock)
        wraps = np.round((np.diff(host_s) - step) / wrap_s)
        elapsed = np.concatenate([[0.0], np.cumsum(step + wraps * wrap_s)])
        return np.asarray(host_s[0] + elapsed, dtype=np.float64)
