"""A gimbal's other axis on the same Modbus line or server (another unit id): moved
between the runs of the axis under test and holding its angle during them, by its own
drive's position mode.

The host moves it along a trapezoid of position setpoints (``[modbus.hold]`` speed and
acceleration), one every :data:`SETPOINT_STEP_S`, each ramped to by the drive over that
time (``setpoint_interpolation_time``), and waits until it stands within ``window_rad`` of
the target, then ``settle_s``. The drive's communication watchdog sees a request from the
host at least every :data:`KEEPALIVE_S` while the axis under test runs
(:meth:`HeldModbusAxis.keepalive`, called from the poll loop): a held axis that faulted or
disabled itself stops the run, naming it.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

from hil.drives.base import DriveState, DriveStatus
from hil.drives.held import trapezoid_rad
from hil.drives.modbus.acquire import Feedback, set_interpolation
from hil.drives.modbus.link import ModbusLink
from hil.drives.modbus.state_machine import ModbusStateMachine
from hil.drives.station import HoldSettings
from hil.errors import DriveFaultError, DriveStateError
from hil.motion import Mode

log = logging.getLogger(__name__)

SETPOINT_STEP_S = 0.02  # between two setpoints of a held axis's move
KEEPALIVE_S = 0.1  # longest silence towards a held axis while the axis under test runs
AT_REST_RAD_S = 0.01  # a held axis this slow is standing


class HeldModbusAxis:
    """The held axis ``name`` at ``unit_id``, on ``link``'s connection.

    Raises (at construction)
    ------------------------
    DriveStateError
        The register map cannot hold an axis (no position mode, no setpoint ramp).
    """

    def __init__(self, link: ModbusLink, *, name: str, unit_id: int, hold: HoldSettings,
                 others: Callable[[], None] = lambda: None) -> None:
        self.link = link.for_unit(unit_id)
        self.name, self.unit_id, self.hold = name, unit_id, hold
        lacking = [what for what, present in (
            ("a 'position' mode", "position" in self.link.map.modes),
            ("'position_cmd'", "position_cmd" in self.link.map.registers),
            ("'setpoint_interpolation_time'",
             "setpoint_interpolation_time" in self.link.map.registers)) if not present]
        if lacking:
            raise DriveStateError(f"{self.link.where} ({name} axis): the register map "
                                  f"{self.link.map.source} has no {', '.join(lacking)}: it "
                                  "cannot hold an axis")
        self.states = ModbusStateMachine(self.link, Feedback(self.link, "instantaneous"))
        self._last_request = 0.0
        self._others = others  # keeps the other drives' watchdogs fed while this one moves

    @property
    def address(self) -> str:
        return f"unit {self.unit_id}"

    @property
    def position_rad(self) -> float:
        return self.states.status().position_rad

    def enable(self) -> None:
        """Position mode holding where it stands, enabled (confirmed)."""
        set_interpolation(self.link, 0.0)
        self.states.enable(Mode.POSITION)
        self._last_request = time.monotonic()

    def keepalive(self) -> None:
        """A request to the held axis when it has had none for :data:`KEEPALIVE_S`: its
        state read, a fault or a disable raised."""
        if time.monotonic() - self._last_request < KEEPALIVE_S:
            return
        self._last_request = time.monotonic()
        # one short request (the poll loop's slack is a few ms): the status word alone
        values = self.link.read_values(("status_word", "fault_code"))
        bits = self.link.map.status_bits
        word = int(values["status_word"])
        if word & 1 << bits["fault"]:
            raise DriveFaultError(f"{self.link.where}: the held {self.name} axis faulted",
                                  code=int(values["fault_code"]))
        if not word & 1 << bits["enabled"]:
            raise DriveStateError(f"{self.link.where}: the held {self.name} axis is no "
                                  "longer holding (disabled)")

    def _check(self, status: DriveStatus) -> None:
        self._last_request = time.monotonic()
        if status.state is DriveState.FAULT:
            raise DriveFaultError(f"{self.link.where}: the held {self.name} axis faulted",
                                  code=status.fault_code or 0)
        if status.state is not DriveState.ENABLED:
            raise DriveStateError(f"{self.link.where}: the held {self.name} axis is no "
                                  f"longer holding (it is {status.state.value})")

    def move_to(self, angle_rad: float) -> None:
        """Move to ``angle_rad`` and hold it (standing within the window, then settled).

        Raises
        ------
        DriveStateError
            Not there within the move's time and ``timeout_s``, or no longer enabled.
        """
        hold = self.hold
        path = trapezoid_rad(self.position_rad, angle_rad, speed_rad_s=hold.speed_rad_s,
                             accel_rad_s2=hold.accel_rad_s2, step_s=SETPOINT_STEP_S)
        set_interpolation(self.link, SETPOINT_STEP_S)
        start = time.monotonic()
        for index, position in enumerate(path):
            self.link.write_value("position_cmd", float(position))
            self._others()
            time.sleep(max(0.0, start + (index + 1) * SETPOINT_STEP_S - time.monotonic()))
        deadline = time.monotonic() + hold.timeout_s
        while True:
            status = self.states.status()
            self._check(status)
            if (abs(status.position_rad - angle_rad) <= hold.window_rad
                    and abs(status.velocity_rad_s) < AT_REST_RAD_S):
                break
            if time.monotonic() > deadline:
                raise DriveStateError(
                    f"{self.link.where}: the held {self.name} axis did not reach "
                    f"{angle_rad:+.4f} rad within {hold.timeout_s:g} s of its move (at "
                    f"{status.position_rad:+.4f} rad)")
            self._others()
            time.sleep(SETPOINT_STEP_S)
        settled = time.monotonic() + hold.settle_s
        while time.monotonic() < settled:
            time.sleep(min(KEEPALIVE_S / 2, max(0.0, settled - time.monotonic())))
            self.keepalive()
            self._others()
        log.info("%s (%s axis) holds %+.4f rad", self.link.where, self.name, angle_rad)

    def disable(self) -> None:
        """Clear its control word (logged when it cannot be confirmed)."""
        self.states.disable()
