"""CanOpenDrive: the Drive contract over a CiA 402 servo on CANopen.

Composed of the link (``link.py``: bus, NMT, SDO, PDO layout, SYNC ticks, heartbeat), the
state machine (``state_machine.py``: enable, mode, disable, quick stop, fault reset) and
the acquisition (``acquire.py``: SYNC-clocked streaming, the drive recorder); this module
brings the node up (scaling, limits, PDO layout, torque sample, control period) and checks
a run against what the link can do before handing it to the acquisition.
"""

from __future__ import annotations

import functools
import logging
import math
from typing import Any

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
from hil.drives.cia402.acquire import RunSetup, recorder_upload, run_recorder, run_stream
from hil.drives.cia402.held_axis import HeldAxis, bus_load
from hil.drives.cia402.link import CanLink
from hil.drives.cia402.map_check import (
    check_objects,
    check_torque_scale,
    mismatch,
    read_object,
)
from hil.drives.cia402.protocol import (
    INTERPOLATION_UNKNOWN,
    TPDO_LAYOUT,
    Scaling,
    max_stream_rate_hz,
    pack_harmonics,
    state_of,
    stream_frame_bytes,
    tpdo_layout_mean,
)
from hil.drives.cia402.state_machine import Cia402StateMachine
from hil.drives.equipment import Equipment, sensor_fields
from hil.drives.held import HeldAxes
from hil.drives.locked import ClampedRotor
from hil.drives.station import CanOpenStation
from hil.drives.transducer import TransducerReader
from hil.errors import DriveError, DriveStateError
from hil.motion import CompensationTable, Excitation, Limits, Mode
from hil.recording import Recording

log = logging.getLogger(__name__)

# CANopen integer types by struct code: (range, name) of what an object can hold
_RANGES = {"H": (0, 0xFFFF, "UNSIGNED16"), "I": (0, 0xFFFFFFFF, "UNSIGNED32"),
           "h": (-0x8000, 0x7FFF, "INTEGER16"), "i": (-0x80000000, 0x7FFFFFFF, "INTEGER32")}
RPM_PER_RAD_S = 60 / (2 * math.pi)  # 0x6080 max motor speed is in rpm


class CanOpenDrive(ClampedRotor, Drive):
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
        self._info: DriveInfo | None = None
        self.scaling: Scaling | None = None
        self.supported_modes = 0
        self.recorder_rate_hz = 0.0
        self.recorder_samples = 0
        self.control_period_s: float | None = None  # the drive's control loop, if it says
        self.command_interpolation = INTERPOLATION_UNKNOWN
        self.torque_sample = "instantaneous"  # or "mean": the map's torque_mean
        self._period_us = round(station.sync_period_s * 1e6)
        self.held: HeldAxes[HeldAxis] = HeldAxes()  # the gimbal's other axes on this bus
        self.bus_load = 0.0  # the fraction of the bus the stream and the heartbeats take
        try:
            self._bring_up()
        except BaseException:
            self.held.release()
            self.link.close()
            raise

    # -- bring-up ----------------------------------------------------------------------
    def _bring_up(self) -> None:
        st, link = self.station, self.link
        rate = 1.0 / st.sync_period_s
        bus_max = max_stream_rate_hz(st.bitrate, st.max_bus_load)
        rpdo_bytes, tpdo_bytes = stream_frame_bytes()
        load = bus_load(st, rpdo_bytes=rpdo_bytes, tpdo_bytes=tpdo_bytes)
        if rate > bus_max or load > st.max_bus_load:
            held = f" with {len(st.held)} held axis node(s)" if st.held else ""
            raise DriveStateError(
                f"SYNC at {rate:.0f} Hz{held} needs {load:.0%} of a {st.bitrate / 1e3:.0f} "
                f"kbit/s bus, more than the station's max_bus_load {st.max_bus_load:.0%} "
                f"(limit {bus_max:.0f} Hz); {st.source}"
            )
        self.bus_load = load
        link.open()
        # many drives power up with no heartbeat (0x1017 = 0, a common factory default):
        # PRE-OPERATIONAL commanded, the heartbeat set by SDO (its answer proves the node is
        # there), then the state confirmed by that heartbeat
        link.command_nmt("PRE-OPERATIONAL")
        link.write(0x1017, 0, round(st.heartbeat_period_s * 1e3))
        link.nmt("PRE-OPERATIONAL")
        check_objects(link, st.object_map)  # the map against the drive, before anything else
        self.scaling = self._scaling()
        self.supported_modes = int(link.read(0x6502))
        self.torque_sample = self._choose_torque_sample()
        mean = st.object_map.torque_mean
        link.configure_pdos(tpdo_layout_mean(mean.index, mean.subindex)
                            if self.torque_sample == "mean" and mean is not None else TPDO_LAYOUT)
        self._write_period(self._period_us)
        link.write(0x1019, 0, 0)  # SYNC without counter
        self._write_limits()
        self._watch_host()
        self._read_control_period()
        self._check_control_period()
        om = st.object_map
        if om.has_recorder and st.acquisition != "stream" and self.control_period_s:
            assert om.recorder_index is not None
            self.recorder_rate_hz = 1.0 / self.control_period_s
            self.recorder_samples = int(link.read(om.recorder_index, 5))
        self.command_interpolation = self._read_interpolation()
        self.states = Cia402StateMachine(
            link,
            scaling=self.scaling,
            supported_modes=self.supported_modes,
            quick_stop_timeout_s=st.state_timeout_s * 3,
        )
        self._info = self._read_info(rate)
        link.nmt("OPERATIONAL")
        status = link.tick_until("first SYNC answer", lambda sw, mode: True)
        log.info("node %d operational, %s", st.node_id, state_of(status[0]))
        for name, node_id in st.held.items():  # the gimbal's other axes, held by their drives
            axis = self.held.axes[name] = HeldAxis(link, name=name, node_id=node_id)
            axis.enable()
            if name in st.gimbal.hold.at_rad:
                axis.move_to(st.gimbal.hold.at_rad[name])

    def _scaling(self) -> Scaling:
        st, link, om = self.station, self.link, self.station.object_map
        rated_torque = int(link.read(0x6076)) / om.rated_torque_per_nm
        rated_current = int(link.read(0x6075)) / om.rated_current_per_a
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
        check_torque_scale(link, om, rated_torque_nm=rated_torque,
                           torque_limit_nm=self.limits.torque_nm)
        return Scaling(
            counts_per_rev=counts,
            velocity_units_per_rad_s=(st.velocity_units_per_rad_s or om.velocity_per_rad_s
                                      or counts / (2 * math.pi)),
            rated_torque_nm=rated_torque,
            rated_current_a=rated_current,
        )

    def _choose_torque_sample(self) -> str:
        """``"mean"`` when the object map gives the SYNC-period torque average (16-bit, so
        it takes 0x6077's place in TPDO2) and the station does not say otherwise; else
        ``"instantaneous"`` (0x6077)."""
        st = self.station
        if st.torque_sample == "instantaneous":
            return "instantaneous"
        assert self.scaling is not None
        ref = st.object_map.torque_mean
        reason = ""
        if ref is None:
            reason = f"the object map '{st.object_map.name}' gives no torque_mean"
        elif ref.bits != 16:
            reason = f"{ref} is not 16-bit: TPDO2 holds velocity, a 16-bit torque and current"
        elif self.limits.torque_nm / self.scaling.rated_torque_nm * ref.per_unit > 32767:
            reason = (f"the torque limit {self.limits.torque_nm:g} N·m exceeds the range of "
                      f"{ref} ({32767 / ref.per_unit:.3g} × rated)")
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

    def _read_control_period(self) -> None:
        """The drive's control period, where the object map says it reports it."""
        om = self.station.object_map
        if om.control_period is None:
            return
        period_s = read_object(self.link, om.control_period, om) / om.control_period.per_unit
        if not 1e-6 <= period_s <= 0.01:
            raise mismatch(self.link, om, f"reads {om.control_period} as a control period of "
                                          f"{period_s:g} s (plausible 1 µs to 10 ms)")
        self.control_period_s = period_s

    def _check_control_period(self) -> None:
        """The drive's control period: as it reports it (the map's ``control_period``),
        else the station's ``control_period_s``; both given must agree."""
        st = self.station
        if st.control_period_s is None:
            return
        if self.control_period_s is None:
            self.control_period_s = st.control_period_s
        elif not math.isclose(self.control_period_s, st.control_period_s, rel_tol=1e-6):
            raise DriveStateError(
                f"node {st.node_id}: control period {st.object_map.control_period} is "
                f"{self.control_period_s:g} s, "
                f"the station file {st.source} says {st.control_period_s:g} s"
            )

    def _read_interpolation(self) -> str:
        """How the drive moves from one cyclic-synchronous target to the next (0x60C0)."""
        try:
            code = int(self.link.read(0x60C0))
        except (DriveStateError, KeyError):
            return INTERPOLATION_UNKNOWN
        codes = self.station.object_map.interpolation_codes
        return codes.get(code, f"{INTERPOLATION_UNKNOWN} (0x60C0 = {code})")

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
        self.link.sync_period_s = period_us / 1e6  # the SYNCs we send keep this period

    def _write_limits(self) -> None:
        """The unit's limits into the drive, so that it enforces them itself: 0x6072 max
        torque, 0x607F max profile velocity; the motion monitor's envelope (the limits and
        their stated margin, :class:`MotionEnvelope`) as 0x607D software position limits
        and 0x6080 max motor speed; the quick stop (0x605A, 0x6085). A value the object
        cannot hold is refused here, in one line, before any motion."""
        assert self.scaling is not None
        sc, lim, st = self.scaling, self.limits, self.station
        envelope = MotionEnvelope.of(lim)
        for index, sub, code, value, what in (
            (0x6072, 0, "H", round(lim.torque_nm / sc.rated_torque_nm * 1e3),
             f"torque limit {lim.torque_nm:g} N·m (‰ of rated)"),
            (0x607F, 0, "I", round(lim.velocity_rad_s * sc.velocity_units_per_rad_s),
             f"velocity limit {lim.velocity_rad_s:g} rad/s"),
            (0x607D, 1, "i", math.floor(envelope.position_min_rad * sc.counts_per_rad),
             f"travel_min_rad {lim.travel_min_rad:g} rad (with the monitor's margin)"),
            (0x607D, 2, "i", math.ceil(envelope.position_max_rad * sc.counts_per_rad),
             f"travel_max_rad {lim.travel_max_rad:g} rad (with the monitor's margin)"),
            (0x6080, 0, "I", math.ceil(envelope.velocity_rad_s * RPM_PER_RAD_S),
             f"velocity limit {lim.velocity_rad_s:g} rad/s with the monitor's margin (rpm)"),
            (0x605A, 0, "h", st.quick_stop_option_code, "quick_stop_option_code"),
            (0x6085, 0, "I", round(st.quick_stop_decel_rad_s2 * sc.velocity_units_per_rad_s),
             f"quick_stop_decel_rad_s2 {st.quick_stop_decel_rad_s2:g}"),
        ):
            self._write_object(index, sub, code, value, what)

    def _watch_host(self) -> None:
        """A dead host stops the axis: our heartbeat (node ``host_node_id``) starts, the
        drive consumes it (0x1016:1 = node << 16 | time in ms) and reacts to its loss by
        0x6007 (abort connection option code; the station's default 3 is quick stop)."""
        st = self.station
        self.link.start_host_heartbeat()
        timeout_ms = round(st.host_heartbeat_timeout_s * 1e3)
        self._write_object(0x1016, 1, "I", st.host_node_id << 16 | timeout_ms,
                           f"consumer heartbeat time {st.host_heartbeat_timeout_s:g} s")
        self._write_object(0x6007, 0, "h", st.abort_connection_option_code,
                           "abort_connection_option_code")

    def _write_object(self, index: int, sub: int, code: str, value: int, what: str) -> None:
        """Write an integer object, refusing in one line a value it cannot hold; by raw SDO
        with its standard type when the station's EDS does not declare it."""
        low, high, kind = _RANGES[code]
        st = self.station
        if not low <= value <= high:
            raise DriveStateError(
                f"node {st.node_id}: {what} is {value} in 0x{index:04X}:{sub:02X} ({kind}, "
                f"{low}..{high}): the drive cannot represent it; {st.source}"
            )
        self.link.write_standard(index, sub, code, value)

    def _read_info(self, rate_hz: float) -> DriveInfo:
        link, st = self.link, self.station
        assert self.scaling is not None
        return DriveInfo(
            vendor=f"vendor 0x{int(link.read(0x1018, 1)):08X}",
            model=str(link.read(0x1008)),
            firmware_version=str(link.read(0x100A)),
            serial=str(link.read(0x1018, 4)),
            rated_torque_nm=self.scaling.rated_torque_nm,
            limits=self.limits,
            modes=self.states.modes(),
            max_sample_rate_hz=max(rate_hz, self.recorder_rate_hz),
            capabilities=st.equipment.capabilities() | frozenset(
                ({Capability.COMPENSATION_TABLE}
                 if st.object_map.compensation_index is not None else set())
                | ({Capability.ELEVATION_AXIS} if "elevation" in st.held else set())
                | ({Capability.ELEVATION_MOTION} if self._elevation_follows else set())),
            recorder=Recorder(stream_rate_hz=rate_hz, samples=self.recorder_samples)
            if self.recorder_rate_hz > rate_hz else None,
            **sensor_fields(st.equipment),
            timing={**st.object_map.conventions(), "torque_sample": self.torque_sample,
                    **({} if self.control_period_s is None
                       else {"control_period_s": f"{self.control_period_s:g}"})},
            transport=f"canopen {st.interface}:{st.channel} node {st.node_id}",
        )

    @property
    def _elevation_follows(self) -> bool:
        """The held elevation can follow a path while this axis runs: this node's runs
        above the stream rate play on its recorder, the elevation node has one too (the
        station's object map), and the host produces the SYNC (both tables start before
        the same one)."""
        st = self.station
        return ("elevation" in st.held and self.recorder_rate_hz > 0
                and st.object_map.has_recorder and st.sync_producer == "host")

    # -- the contract ---------------------------------------------------------------------
    @property
    def info(self) -> DriveInfo:
        """What the node is and can do (read at bring-up)."""
        assert self._info is not None
        return self._info

    @property
    def stream_rate_hz(self) -> float:
        """The station's SYNC rate: the fastest a run can be streamed."""
        return 1.0 / self.station.sync_period_s

    @property
    def mode_code(self) -> int | None:
        """The CiA 402 operation mode (0x6060) selected last, None before any."""
        return self.states.mode_code

    def status(self) -> DriveStatus:
        """The node's state, position and velocity, read by SDO."""
        return self.states.status()

    def enable(self, mode: Mode = Mode.VELOCITY) -> None:
        """Reset a fault (verified), select ``mode`` (cyclic synchronous where the node has
        it), and enable operation, each step confirmed by the statusword.

        Parameters
        ----------
        mode : Mode
            The excitation mode the next runs use (a run in another mode switches).

        Raises
        ------
        DriveFaultError
            The node faulted, or a fault reset did not clear its fault.
        DriveStateError
            A state or the mode was not confirmed in the station's state timeout.
        """
        self.states.enable(mode)

    def disable(self) -> None:
        """Shutdown, confirmed; idempotent, and best effort on a lost link."""
        self.states.disable()

    def quick_stop(self) -> None:
        """Quick stop by the drive's ramp (0x605A, 0x6085), confirmed at rest."""
        self.states.quick_stop()

    def load_compensation(self, table: CompensationTable | None) -> None:
        """Download a cogging compensation table into the object map's compensation table
        (``None``: an empty one).

        Raises
        ------
        DriveStateError
            The object map gives no compensation table.
        """
        index = self.station.object_map.compensation_index
        if index is None:
            raise self._without(Capability.COMPENSATION_TABLE)
        cogging = () if table is None else table.cogging_nm
        ripple = () if table is None else table.kt_ripple
        self.link.write(index, 1, pack_harmonics(cogging))
        self.link.write(index, 2, pack_harmonics(ripple))

    def set_elevation(self, elevation_rad: float) -> None:
        """Move the gimbal's elevation axis (a held node on this bus) to ``elevation_rad``
        and hold it there, the axis under test holding still meanwhile.

        Raises
        ------
        DriveStateError
            The station holds no elevation axis, or it did not reach the angle in time.
        """
        if not self.held.move("elevation", elevation_rad):
            super().set_elevation(elevation_rad)

    def close(self) -> None:
        """Disable (the held axes first), return the node to PRE-OPERATIONAL, stop watching
        our heartbeat (a clean end is no lost host), release the bus."""
        try:
            self._close_transducer()
            self.held.release()
            self.disable()
            if self.link.connected:
                try:
                    self.link.nmt("PRE-OPERATIONAL", timeout_s=0.5)
                    self._write_object(0x1016, 1, "I", 0, "consumer heartbeat off")
                except DriveError as exc:
                    log.warning("node %d: %s", self.station.node_id, exc)
        finally:
            self.link.close()

    def run(self, excitation: Excitation) -> Recording:
        """Run ``excitation``: streamed one sample per SYNC up to the SYNC rate, above it by
        the drive recorder (rates ``recorder_rate_hz / n``). See :meth:`Drive.run`.

        Raises
        ------
        DriveStateError
            The drive is not enabled, the rate is not one this link can do, or the mode is
            refused; nothing moved.
        LimitViolationError
            The command leaves the unit's limits; nothing moved.
        DriveError
            The run was cut short (the drive made safe, the partial recording attached),
            or lost more rows than the station allows.
        """
        if self.states.state is not DriveState.ENABLED:
            raise DriveStateError(
                f"cannot run '{excitation.name}': drive is {self.states.state.value}"
            )
        fs = excitation.fs_hz
        use_recorder = self.recorder_rate_hz > 0 and fs > self.stream_rate_hz
        if use_recorder and self._shaft is not None:
            raise DriveStateError(
                f"excitation '{excitation.name}' at {fs:g} Hz would run on the drive "
                "recorder, which does not record the station's torque transducer: stream it "
                f"(at most {self.stream_rate_hz:g} Hz)")
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
        follower = self._follower(excitation, use_recorder=use_recorder)
        start = self.status()
        check_limits(excitation, self.limits, start_position_rad=start.position_rad)
        if excitation.mode is not self.link.mode:
            self.states.select_mode(excitation.mode)
        if not use_recorder and round(1e6 / fs) != self._period_us:
            self._write_period(round(1e6 / fs))
        acquire = (functools.partial(run_recorder, follower=follower) if use_recorder
                   else run_stream)
        shaft = self._shaft
        if shaft is not None:
            self._read_shaft(shaft, fs)
        try:
            acquired = acquire(self.link, self._run_setup(), excitation)
        except DriveError:
            raise
        except KeyboardInterrupt as stop:  # the recorder's run (or a stream not begun)
            self.states.quick_stop()
            raise interrupted(stop, self._recorded(excitation) if use_recorder
                              else None) from stop
        except BaseException:
            self.states.quick_stop()
            raise
        if acquired.stop is not None:  # a stop signal: quick stop, the rows so far kept
            self.states.quick_stop()
            raise interrupted(acquired.stop, acquired.recording) from acquired.stop
        if acquired.failure is not None:
            self.states.make_safe(acquired.failure)
            acquired.failure.partial_recording = acquired.recording
            raise acquired.failure
        if shaft is not None:
            self.link.in_step = None
            return shaft.on_rows(acquired.recording)
        return acquired.recording

    def _follower(self, excitation: Excitation, *, use_recorder: bool) -> HeldAxis | None:
        """The held elevation that follows ``excitation``'s elevation path, if it has one.

        Raises
        ------
        DriveStateError
            The station cannot move the elevation along a path, or the run would be
            streamed (the path plays on the elevation's recorder, beside this axis's).
        """
        if excitation.elevation_path_rad is None:
            return None
        if not self._elevation_follows:
            raise self._without(Capability.ELEVATION_MOTION)
        if not use_recorder:
            raise DriveStateError(
                f"excitation '{excitation.name}' at {excitation.fs_hz:g} Hz would be streamed: "
                "the elevation follows its path on its own drive recorder, started with this "
                f"axis's, at {self.recorder_rate_hz:g} Hz / n above {self.stream_rate_hz:g} Hz")
        return self.held.axes["elevation"]

    def _read_shaft(self, shaft: TransducerReader, fs_hz: float) -> None:
        """The transducer read through the run, each reading stamped with the SYNCs since
        its first row: in step with each SYNC in lockstep, else on its own thread."""
        first = self.link.sync_index + 1
        clock_s = lambda: (self.link.sync_index - first) / fs_hz  # noqa: E731
        if self.station.sync_pacing == "lockstep":
            shaft.begin(clock_s)
            self.link.in_step = shaft.read_in_step
        else:
            shaft.start(clock_s)

    def _clamp_equipment(self) -> Equipment:
        return self.station.equipment

    def _check_rate_hz(self) -> float:
        return self.stream_rate_hz

    def _released(self) -> None:
        self.link.in_step = None

    def _set_clamp(self, engaged: bool) -> None:
        """The fixture's drive output (CiA 402 digital outputs 0x60FE:01; sub 2 the mask
        of the outputs written)."""
        fixture = self.station.equipment.locked_rotor
        assert fixture is not None
        bit = 1 << fixture.output_bit
        self.link.write_standard(0x60FE, 2, "I", bit)
        self.link.write_standard(0x60FE, 1, "I", bit if engaged else 0)

    def _recorded(self, excitation: Excitation) -> Recording | None:
        """After a stop signal (the drive quick-stopped): what the drive recorder holds of
        ``excitation``, or ``None`` when it cannot be uploaded (logged)."""
        try:
            divider = round(self.recorder_rate_hz / excitation.fs_hz)
            return recorder_upload(self.link, self._run_setup(), excitation, divider)
        except (DriveError, ValueError) as exc:
            log.warning("node %d: the drive recorder's samples of '%s' not uploaded: %s",
                        self.station.node_id, excitation.name, exc)
            return None

    def _run_setup(self) -> RunSetup:
        assert self.scaling is not None
        info, st = self.info, self.station
        om = st.object_map
        mode_code = self.states.mode_code
        return RunSetup(
            node_id=st.node_id,
            sync_period_s=self.link.sync_period_s,
            lost_sample_fraction=st.lost_sample_fraction,
            scaling=self.scaling,
            envelope=MotionEnvelope.of(self.limits),
            torque_sample=self.torque_sample,
            torque_per_rated=(om.torque_mean.per_unit if self.torque_sample == "mean"
                              and om.torque_mean is not None else 1e3),
            command_interpolation=self.command_interpolation,
            control_period_s=self.control_period_s,
            recorder_rate_hz=self.recorder_rate_hz,
            recorder_index=om.recorder_index,
            waveform_index=om.waveform_index,
            conventions=om.conventions(),
            identity={
                "drive": f"canopen node {st.node_id}",
                "node_id": str(st.node_id),
                "vendor": info.vendor,
                **info.identity(),
                **({"held_axes": self.held.text()} if self.held.axes else {}),
            },
            operation_mode="" if mode_code is None else str(mode_code),
        )
