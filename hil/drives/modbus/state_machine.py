"""The CiA-style state machine of a Modbus drive, through its control and status words:
enable (with fault reset), mode selection, disable, quick stop, and the contract's status.
It knows the link and the feedback reader, nothing of polled runs."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

from hil.drives.base import DriveState, DriveStatus
from hil.drives.modbus.acquire import Feedback
from hil.drives.modbus.link import ModbusLink
from hil.errors import DriveError, DriveFaultError, DriveStateError
from hil.motion import Mode

log = logging.getLogger(__name__)

STATE_TIMEOUT_S = 2.0  # enable, fault reset, disable
QUICK_STOP_TIMEOUT_S = 5.0  # to rest by the drive's ramp
POLL_PAUSE_S = 0.005  # between two status reads while waiting


class ModbusStateMachine:
    """Power state and mode of a Modbus drive.

    Parameters
    ----------
    link : ModbusLink
        The drive's link (and register map).
    feedback : Feedback
        The feedback reader (status word, position, velocity, fault code).

    Attributes
    ----------
    state : DriveState
        The state the contract last put the drive in (checked before a run).
    mode : Mode or None
        The mode selected last, None before any.
    """

    def __init__(self, link: ModbusLink, feedback: Feedback) -> None:
        self.link = link
        self.feedback = feedback
        self.state = DriveState.DISABLED
        self.mode: Mode | None = None

    def status(self) -> DriveStatus:
        """The drive's state (from its status-word bits), position and velocity."""
        _, v = self.feedback.read()
        bit = self.feedback.bit
        if bit(v, "fault"):
            state = DriveState.FAULT
        elif bit(v, "quick_stop_active"):
            state = DriveState.QUICK_STOPPED
        elif bit(v, "enabled"):
            state = DriveState.ENABLED
        else:
            state = DriveState.DISABLED
        return DriveStatus(
            state=state,
            position_rad=v["position"],
            velocity_rad_s=v["velocity"],
            fault_code=int(v["fault_code"]) if state is DriveState.FAULT else None,
        )

    def _control(self, *bits: str) -> None:
        word = sum(1 << self.link.map.control_bits[b] for b in bits)
        self.link.write_value("control_word", word)

    def _await(
        self,
        what: str,
        done: Callable[[dict[str, float]], bool],
        timeout_s: float = STATE_TIMEOUT_S,
    ) -> dict[str, float]:
        deadline = time.monotonic() + timeout_s
        while True:
            _, values = self.feedback.read()
            if done(values):
                return values
            if time.monotonic() > deadline:
                raise DriveStateError(
                    f"{self.link.where}: {what} not confirmed "
                    f"(status word 0x{int(values['status_word']):04X})"
                )
            time.sleep(POLL_PAUSE_S)

    def enable(self, mode: Mode) -> None:
        """Reset a fault, select ``mode`` (holding the axis), set the enable bit, confirmed.

        Raises
        ------
        DriveFaultError
            The drive is in fault after enabling (its fault code attached).
        DriveStateError
            The reset, the mode or the enable was not confirmed.
        """
        bit = self.feedback.bit
        _, values = self.feedback.read()
        if bit(values, "fault"):
            code = int(values["fault_code"])
            self._control("fault_reset")
            self._control()
            self._await("fault reset", lambda v: not bit(v, "fault"))
            log.info("%s: fault 0x%04X reset", self.link.where, code)
        self.select(mode)
        self._control("enable")
        self._await("enable", lambda v: bit(v, "enabled") or bit(v, "fault"))
        self.raise_if_faulted("while enabling")
        self.state = DriveState.ENABLED

    def select(self, mode: Mode) -> None:
        """Write the hold command of ``mode``, then the mode register, and read it back.

        Raises
        ------
        DriveStateError
            The mode register does not show ``mode``.
        """
        self.hold(mode)
        code = self.link.map.modes[mode.value]
        self.link.write_value("mode", code)
        if int(self.link.read_values(("mode",))["mode"]) != code:
            raise DriveStateError(f"{self.link.where}: mode register does not show {mode.value}")
        self.mode = mode

    def hold(self, mode: Mode) -> None:
        """Command the axis to stay: zero torque or velocity, or the present position."""
        value = 0.0
        if mode is Mode.POSITION:
            value = self.link.read_values(("position",))["position"]
        self.link.write_value(f"{mode.value}_cmd", value)

    def raise_if_faulted(self, context: str) -> None:
        """Raise :class:`DriveFaultError` (and note FAULT) if the fault bit is set."""
        _, values = self.feedback.read()
        if self.feedback.bit(values, "fault"):
            self.state = DriveState.FAULT
            raise DriveFaultError(
                f"{self.link.where}: drive fault {context}", code=int(values["fault_code"])
            )

    def disable(self) -> None:
        """Clear the control word, confirmed by the enabled bit; logs what it cannot do."""
        if not self.link.connected:
            self.state = DriveState.DISABLED
            return
        try:
            self._control()
            self._await("disable", lambda v: not self.feedback.bit(v, "enabled"))
            if self.state is not DriveState.DISABLED:
                log.info("%s: drive disabled", self.link.where)
        except DriveError as exc:
            log.error("%s: disable not confirmed: %s", self.link.where, exc)
        self.state = DriveState.DISABLED

    def send_quick_stop(self) -> None:
        """Set the quick-stop bit at once, unconfirmed: the motion monitor's trip, before
        anything else is done (:meth:`quick_stop` then confirms)."""
        try:
            self._control("quick_stop")
        except DriveError as exc:
            log.error("%s: quick stop not sent at the trip: %s", self.link.where, exc)

    def quick_stop(self) -> None:
        """Set the quick-stop bit (reconnecting first if the link dropped), confirmed when
        the drive is no longer enabled and at rest; logs what it cannot confirm."""
        try:
            if not self.link.connected:
                self.link.connect()  # the drive's watchdog stops it anyway; try to confirm
            self._control("quick_stop")
            self._await(
                "quick stop",
                lambda v: not self.feedback.bit(v, "enabled") and abs(v["velocity"]) < 1e-2,
                timeout_s=QUICK_STOP_TIMEOUT_S,
            )
            log.info("%s: quick-stopped, at rest", self.link.where)
        except DriveError as exc:
            log.error("%s: quick stop not confirmed: %s", self.link.where, exc)
        self.state = DriveState.QUICK_STOPPED

    def make_safe(self, error: DriveError) -> None:
        """After a failed run: note a fault, quick stop, disable."""
        if isinstance(error, DriveFaultError):
            self.state = DriveState.FAULT
        self.quick_stop()
        self.disable()
