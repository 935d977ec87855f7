"""CanOpenDrive: the Drive contract over a CiA 402 servo on CANopen."""

from __future__ import annotations

import logging
import math
import time
from typing import Any

from hil.drives.base import Drive, DriveInfo, DriveState, DriveStatus, check_limits
from hil.drives.cia402 import acquire
from hil.drives.cia402.link import CanLink
from hil.drives.cia402.protocol import (
    CW_DISABLE_VOLTAGE,
    CW_ENABLE_OPERATION,
    CW_FAULT_RESET,
    CW_QUICK_STOP,
    CW_SHUTDOWN,
    CW_SWITCH_ON,
    INTERPOLATION_CODES,
    INTERPOLATION_UNKNOWN,
    MODE_CANDIDATES,
    MODE_SUPPORT_BIT,
    SW_FAULT,
    TORQUE_MEAN_NAME,
    TORQUE_MEAN_OBJECT,
    TORQUE_MEAN_PER_RATED,
    TPDO_LAYOUT,
    TPDO_LAYOUT_MEAN,
    Scaling,
    max_stream_rate_hz,
    state_of,
)
from hil.drives.station import CanOpenStation
from hil.errors import DriveCommunicationError, DriveError, DriveFaultError, DriveStateError
from hil.motion import Excitation, Limits, Mode
from hil.recording import Recording

log = logging.getLogger(__name__)


class CanOpenDrive(Drive):
    """A CiA 402 drive: NMT bring-up, checked state machine, SYNC-clocked PDO streaming.

    Parameters
    ----------
    station : CanOpenStation
        Bus, node, object dictionary, SYNC period and scaling.
    limits : Limits
        The unit's envelope: refused before motion, and written to the drive (0x6072,
        0x607F, 0x607D) so that it enforces them too.
    """

    def __init__(self, station: CanOpenStation, *, limits: Limits) -> None:
        self.station = station
        self.limits = limits
        self.link = CanLink(station)
        self._state = DriveState.DISABLED
        self._info: DriveInfo | None = None
        self.scaling: Scaling | None = None
        self.supported_modes = 0
        self.recorder_rate_hz = 0.0
        self.control_period_s: float | None = None  # the drive's control loop, if it says
        self.command_interpolation = INTERPOLATION_UNKNOWN
        self.torque_sample = "instantaneous"  # or "mean": 0x2077 over the SYNC period
        self._period_us = round(station.sync_period_s * 1e6)
        try:
            self._bring_up()
        except BaseException:
            self.link.close()
            raise

    # -- bring-up ----------------------------------------------------------------------
    def _bring_up(self) -> None:
        st, link = self.station, self.link
        rate = 1.0 / st.sync_period_s
        bus_max = max_stream_rate_hz(st.bitrate, st.max_bus_load)
        if rate > bus_max:
            raise DriveStateError(
                f"SYNC at {rate:.0f} Hz needs more than {st.max_bus_load:.0%} of a "
                f"{st.bitrate / 1e3:.0f} kbit/s bus (limit {bus_max:.0f} Hz); {st.source}"
            )
        link.open()
        link.nmt("PRE-OPERATIONAL")  # also proves the node is alive (heartbeat)
        link.write(0x1017, 0, round(st.heartbeat_period_s * 1e3))
        link.nmt("PRE-OPERATIONAL")
        self.scaling = self._scaling()
        self.supported_modes = int(link.read(0x6502))
        self.torque_sample = self._choose_torque_sample()
        link.configure_pdos(TPDO_LAYOUT_MEAN if self.torque_sample == "mean" else TPDO_LAYOUT)
        self._write_period(self._period_us)
        link.write(0x1019, 0, 0)  # SYNC without counter
        self._write_limits()
        try:
            loop_us = int(link.read(0x2200, 6))
            self.control_period_s = loop_us * 1e-6
            self.recorder_rate_hz = 1e6 / loop_us if st.acquisition != "stream" else 0.0
        except (DriveStateError, KeyError):
            self.recorder_rate_hz = 0.0
        self._check_control_period()
        self.command_interpolation = self._read_interpolation()
        self._info = self._read_info(rate)
        link.nmt("OPERATIONAL")
        status = link.tick_until("first SYNC answer", lambda sw, mode: True)
        log.info("node %d operational, %s", st.node_id, state_of(status[0]))

    def _scaling(self) -> Scaling:
        st, link = self.station, self.link
        rated_torque = int(link.read(0x6076)) / 1e3
        rated_current = int(link.read(0x6075)) / 1e3
        counts = int(link.read(0x608F, 1)) // max(1, int(link.read(0x608F, 2)))
        for name, drive_value, station_value in (
            ("rated torque 0x6076", rated_torque, st.rated_torque_nm),
            ("rated current 0x6075", rated_current, st.rated_current_a),
            ("encoder increments 0x608F", counts, st.counts_per_rev),
        ):
            if station_value is not None and not math.isclose(
                drive_value, station_value, rel_tol=1e-3
            ):
                raise DriveStateError(
                    f"node {st.node_id}: {name} is {drive_value:g}, the station file "
                    f"{st.source} says {station_value:g}"
                )
        return Scaling(
            counts_per_rev=counts,
            velocity_units_per_rad_s=st.velocity_units_per_rad_s or counts / (2 * math.pi),
            rated_torque_nm=rated_torque,
            rated_current_a=rated_current,
        )

    def _choose_torque_sample(self) -> str:
        """``"mean"`` when the drive offers the SYNC-period torque average (0x2077 in its
        EDS, by name and type: a manufacturer-specific index means something else on
        another vendor's drive) and the station does not say otherwise; else
        ``"instantaneous"`` (0x6077)."""
        st = self.station
        if st.torque_sample == "instantaneous":
            return "instantaneous"
        assert self.node_od is not None
        assert self.scaling is not None
        obj = self.node_od.get(TORQUE_MEAN_OBJECT)
        offered = (
            obj is not None
            and getattr(obj, "name", "") == TORQUE_MEAN_NAME
            and getattr(obj, "data_type", None) == 0x0003  # INTEGER16
            and bool(getattr(obj, "pdo_mappable", False))
        )
        # INTEGER16 at 0.1 ‰ spans ±3.28 × rated: the torque limit (0x6072) must fit
        fits = self.limits.torque_nm / self.scaling.rated_torque_nm * TORQUE_MEAN_PER_RATED
        reason = ""
        if not offered:
            reason = f"its EDS has no 0x{TORQUE_MEAN_OBJECT:04X} '{TORQUE_MEAN_NAME}'"
        elif fits > 32767:
            reason = (
                f"the torque limit {self.limits.torque_nm:g} N·m exceeds the range of "
                f"0x{TORQUE_MEAN_OBJECT:04X} (3.28 × rated)"
            )
        if not reason:
            return "mean"
        if st.torque_sample == "mean":
            raise DriveStateError(
                f"node {st.node_id}: torque_sample = 'mean' but {reason}; {st.source}"
            )
        log.info("node %d: instantaneous torque 0x6077 (%s)", st.node_id, reason)
        return "instantaneous"

    @property
    def node_od(self) -> Any:
        """The node's object dictionary (from the station's EDS)."""
        return None if self.link.node is None else self.link.node.object_dictionary

    def _check_control_period(self) -> None:
        """The drive's control period: as it reports it (0x2200:6), else the station's
        ``control_period_s``; both given must agree."""
        st = self.station
        if st.control_period_s is None:
            return
        if self.control_period_s is None:
            self.control_period_s = st.control_period_s
        elif not math.isclose(self.control_period_s, st.control_period_s, rel_tol=1e-6):
            raise DriveStateError(
                f"node {st.node_id}: control period 0x2200:6 is {self.control_period_s:g} s, "
                f"the station file {st.source} says {st.control_period_s:g} s"
            )

    def _read_interpolation(self) -> str:
        """How the drive moves from one cyclic-synchronous target to the next (0x60C0)."""
        try:
            code = int(self.link.read(0x60C0))
        except (DriveStateError, KeyError):
            return INTERPOLATION_UNKNOWN
        return INTERPOLATION_CODES.get(code, f"{INTERPOLATION_UNKNOWN} (0x60C0 = {code})")

    def _write_period(self, period_us: int) -> None:
        mantissa, exponent = period_us, -6
        while (mantissa % 10 == 0 and mantissa > 255) or mantissa > 255:
            if mantissa % 10:
                raise DriveStateError(
                    f"a SYNC period of {period_us} µs cannot be encoded in 0x60C2"
                )
            mantissa, exponent = mantissa // 10, exponent + 1
        self.link.write(0x60C2, 2, exponent)
        self.link.write(0x60C2, 1, mantissa)
        self.link.write(0x1006, 0, period_us)
        self._period_us = period_us

    def _write_limits(self) -> None:
        assert self.scaling is not None
        sc, lim, link = self.scaling, self.limits, self.link
        link.write(0x6072, 0, min(0xFFFF, round(lim.torque_nm / sc.rated_torque_nm * 1e3)))
        link.write(0x607F, 0, round(lim.velocity_rad_s * sc.velocity_units_per_rad_s))
        link.write(0x607D, 1, round(lim.travel_min_rad * sc.counts_per_rad))
        link.write(0x607D, 2, round(lim.travel_max_rad * sc.counts_per_rad))
        link.write(0x605A, 0, self.station.quick_stop_option_code)
        link.write(
            0x6085, 0, round(self.station.quick_stop_decel_rad_s2 * sc.velocity_units_per_rad_s)
        )

    def _read_info(self, rate_hz: float) -> DriveInfo:
        link, st = self.link, self.station
        modes = tuple(
            mode
            for mode, candidates in MODE_CANDIDATES.items()
            if any(self.supported_modes & MODE_SUPPORT_BIT[code] for code, _ in candidates)
        )
        assert self.scaling is not None
        return DriveInfo(
            vendor=f"vendor 0x{int(link.read(0x1018, 1)):08X}",
            model=str(link.read(0x1008)),
            firmware_version=str(link.read(0x100A)),
            serial=str(link.read(0x1018, 4)),
            rated_torque_nm=self.scaling.rated_torque_nm,
            limits=self.limits,
            modes=modes,
            max_sample_rate_hz=max(rate_hz, self.recorder_rate_hz),
            transport=f"canopen {st.interface}:{st.channel} node {st.node_id}",
        )

    # -- the contract ---------------------------------------------------------------------
    @property
    def info(self) -> DriveInfo:
        assert self._info is not None
        return self._info

    @property
    def stream_rate_hz(self) -> float:
        return 1.0 / self.station.sync_period_s

    def status(self) -> DriveStatus:
        assert self.scaling is not None
        link, sc = self.link, self.scaling
        statusword = int(link.read(0x6041))
        state = state_of(statusword)
        drive_state = {
            "OPERATION ENABLED": DriveState.ENABLED,
            "QUICK STOP ACTIVE": DriveState.QUICK_STOPPED,
            "FAULT": DriveState.FAULT,
            "FAULT REACTION ACTIVE": DriveState.FAULT,
        }.get(state, DriveState.DISABLED)
        return DriveStatus(
            state=drive_state,
            position_rad=sc.to_si(Mode.POSITION, int(link.read(0x6064))),
            velocity_rad_s=sc.to_si(Mode.VELOCITY, int(link.read(0x606C))),
            fault_code=int(link.read(0x603F)) if statusword & SW_FAULT else None,
        )

    def enable(self, mode: Mode = Mode.VELOCITY) -> None:
        link = self.link
        link.check()
        link.emcy.clear()
        status = link.tick_until("statusword", lambda sw, m: True)
        if status[0] & SW_FAULT:
            self._reset_fault()
        self._select_mode(mode)
        for word, target in (
            (CW_SHUTDOWN, "READY TO SWITCH ON"),
            (CW_SWITCH_ON, "SWITCHED ON"),
            (CW_ENABLE_OPERATION, "OPERATION ENABLED"),
        ):
            link.controlword = word
            self._await_state(target, allow=("OPERATION ENABLED",) if word == CW_SWITCH_ON else ())
        self._state = DriveState.ENABLED
        log.info("node %d enabled in %s", self.station.node_id, link.mode.value)

    def _await_state(self, target: str, allow: tuple[str, ...] = ()) -> None:
        def reached(statusword: int, _mode: int) -> bool:
            self.link.raise_if_faulted(statusword, f"while going to {target}")
            return state_of(statusword) in (target, *allow)

        self.link.tick_until(target, reached)

    def _reset_fault(self) -> None:
        """Fault reset on a rising edge of bit 7, verified: the fault must clear and stay
        cleared for a few cycles (a reset does not remove the cause)."""
        link = self.link
        code = link.fault_code()
        link.controlword = CW_DISABLE_VOLTAGE
        link.tick()
        link.controlword = CW_FAULT_RESET
        try:
            link.tick_until("fault reset", lambda sw, m: not sw & SW_FAULT)
            for _ in range(3):
                link.tick()
                status = link.latest_status()
                if status is not None and status[0] & SW_FAULT:
                    raise DriveStateError("fault came back")
        except DriveStateError as exc:
            raise DriveFaultError(
                f"node {self.station.node_id}: fault reset did not clear the fault ({exc})",
                code=link.fault_code() or code,
            ) from exc
        finally:
            link.controlword = CW_DISABLE_VOLTAGE
        link.emcy.clear()
        log.info("node %d: fault 0x%04X reset", self.station.node_id, code)

    def _select_mode(self, mode: Mode) -> None:
        """Pick the cyclic synchronous mode (else the profile mode) and verify 0x6061."""
        link = self.link
        for code, name in MODE_CANDIDATES[mode]:  # noqa: B007 (used after the loop)
            if self.supported_modes & MODE_SUPPORT_BIT[code]:
                break
        else:
            raise DriveStateError(f"node {self.station.node_id} supports no {mode.value} mode")
        assert self.scaling is not None
        hold = 0
        if mode is Mode.POSITION:
            hold = int(link.read(0x6064))
        link.mode, link.target = mode, hold
        if code == 3:  # profile velocity: no ramp of our own on top of the excitation
            link.write(0x6083, 0, 0xFFFFFFFF)
            link.write(0x6084, 0, 0xFFFFFFFF)
        if code == 4:
            link.write(0x6087, 0, 0xFFFFFFFF)
        link.write(0x6060, 0, code)
        link.tick_until(f"mode {name} (0x6061 = {code})", lambda sw, m: m == code)
        if int(link.read(0x6061)) != code:
            raise DriveStateError(f"node {self.station.node_id}: 0x6061 does not show mode {code}")
        self.mode_code = code
        log.info("node %d: mode %s", self.station.node_id, name)

    def disable(self) -> None:
        if not self.link.connected:
            self._state = DriveState.DISABLED
            return
        try:
            self.link.controlword = CW_SHUTDOWN
            self.link.check()
            self.link.tick_until(
                "disable",
                lambda sw, m: state_of(sw) in ("READY TO SWITCH ON", "SWITCH ON DISABLED", "FAULT"),
            )
        except DriveError as exc:
            log.error("node %d: disable not confirmed: %s", self.station.node_id, exc)
            self._best_effort(CW_DISABLE_VOLTAGE)
        self._state = DriveState.DISABLED

    def quick_stop(self) -> None:
        if not self.link.connected:
            return
        link = self.link
        link.controlword = CW_QUICK_STOP
        try:
            link.check()
            deadline = time.monotonic() + self.station.state_timeout_s * 3
            while time.monotonic() < deadline:
                status = link.latest_status() if link.tick() else None
                if status is None:
                    status = int(link.read(0x6041)), 0
                state = state_of(status[0])
                if state in ("SWITCH ON DISABLED", "FAULT"):
                    break
                if state == "QUICK STOP ACTIVE" and abs(self.status().velocity_rad_s) < 1e-2:
                    break
            else:
                raise DriveStateError("axis not at rest after the quick-stop timeout")
        except DriveError as exc:
            log.error("node %d: quick stop not confirmed: %s", self.station.node_id, exc)
            self._best_effort(CW_QUICK_STOP)
        self._state = DriveState.QUICK_STOPPED

    def _best_effort(self, controlword: int) -> None:
        """The receiver died or the drive is mute: restart reception, send the controlword
        by SDO and as RPDO, and confirm by SDO if the node answers."""
        link = self.link
        link.restart_receiver()
        link.controlword = controlword
        for _ in range(3):
            try:
                link.tick()
            except DriveError:
                break
        try:
            link.write(0x6040, 0, controlword)
            log.warning("node %d now %s", self.station.node_id, state_of(int(link.read(0x6041))))
        except DriveError as exc:
            log.error("node %d: cannot confirm a safe state: %s", self.station.node_id, exc)

    def close(self) -> None:
        try:
            self.disable()
            if self.link.connected:
                try:
                    self.link.nmt("PRE-OPERATIONAL", timeout_s=0.5)
                except DriveError as exc:
                    log.warning("node %d: %s", self.station.node_id, exc)
        finally:
            self.link.close()

    def run(self, excitation: Excitation) -> Recording:
        if self._state is not DriveState.ENABLED:
            raise DriveStateError(f"cannot run '{excitation.name}': drive is {self._state.value}")
        fs = excitation.fs_hz
        use_recorder = self.recorder_rate_hz > 0 and fs > self.stream_rate_hz
        if use_recorder:
            divider = self.recorder_rate_hz / fs
            if abs(divider - round(divider)) > 1e-9:
                raise DriveStateError(
                    f"excitation '{excitation.name}' at {fs} Hz: the drive recorder samples at "
                    f"{self.recorder_rate_hz:g} Hz / n; streaming supports up to "
                    f"{self.stream_rate_hz:g} Hz"
                )
        else:
            period_us = 1e6 / fs
            if fs > self.stream_rate_hz * (1 + 1e-9) or abs(period_us - round(period_us)) > 1e-6:
                raise DriveStateError(
                    f"excitation '{excitation.name}' is sampled at {fs} Hz; this CANopen "
                    f"link streams at up to {self.stream_rate_hz:g} Hz (SYNC period in whole µs)"
                )
        start = self.status()
        check_limits(excitation, self.limits, start_position_rad=start.position_rad)
        if excitation.mode is not self.link.mode:
            self._select_mode(excitation.mode)
        if use_recorder:
            return acquire.run_recorder(self, excitation)
        if round(1e6 / fs) != self._period_us:
            self._write_period(round(1e6 / fs))
        return acquire.run_stream(self, excitation)

    def mark_faulted(self) -> None:
        self._state = DriveState.FAULT

    def comm_error(self, message: str) -> DriveCommunicationError:
        return DriveCommunicationError(f"node {self.station.node_id}: {message}")
