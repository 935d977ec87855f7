"""The CiA 402 state machine of one node, driven over its :class:`CanLink`: enable (with a
verified fault reset), mode selection, disable, quick stop, and making the node safe after
a failed run. It knows the link and the CiA 402 vocabulary, nothing of acquisition."""

from __future__ import annotations

import logging
import time

from hil.drives.base import DriveState, DriveStatus
from hil.drives.cia402.link import CanLink
from hil.drives.cia402.protocol import (
    CW_DISABLE_VOLTAGE,
    CW_ENABLE_OPERATION,
    CW_FAULT_RESET,
    CW_QUICK_STOP,
    CW_SHUTDOWN,
    CW_SWITCH_ON,
    MODE_CANDIDATES,
    MODE_SUPPORT_BIT,
    SW_FAULT,
    Scaling,
    state_of,
)
from hil.errors import DriveError, DriveFaultError, DriveStateError
from hil.motion import Mode

log = logging.getLogger(__name__)

_CONTRACT_STATE = {
    "OPERATION ENABLED": DriveState.ENABLED,
    "QUICK STOP ACTIVE": DriveState.QUICK_STOPPED,
    "FAULT": DriveState.FAULT,
    "FAULT REACTION ACTIVE": DriveState.FAULT,
}


class Cia402StateMachine:
    """Power state and operation mode of one CiA 402 node.

    Parameters
    ----------
    link : CanLink
        The node's open link (SDO, the cyclic exchange, EMCY).
    scaling : Scaling
        Drive units <-> SI, read at bring-up.
    supported_modes : int
        The node's 0x6502 (supported drive modes bit field).
    quick_stop_timeout_s : float
        How long a quick stop may take to bring the axis to rest.

    Attributes
    ----------
    state : DriveState
        The state the contract last put the drive in (checked before a run).
    mode_code : int or None
        The CiA 402 operation mode (0x6060) selected last, None before any.
    """

    def __init__(
        self,
        link: CanLink,
        *,
        scaling: Scaling,
        supported_modes: int,
        quick_stop_timeout_s: float,
    ) -> None:
        self.link = link
        self.scaling = scaling
        self.supported_modes = supported_modes
        self.quick_stop_timeout_s = quick_stop_timeout_s
        self.state = DriveState.DISABLED
        self.mode_code: int | None = None

    @property
    def node_id(self) -> int:
        """The node's CANopen id (for messages)."""
        return self.link.node_id

    def modes(self) -> tuple[Mode, ...]:
        """The excitation modes the node offers (cyclic synchronous or profile)."""
        return tuple(
            mode
            for mode, candidates in MODE_CANDIDATES.items()
            if any(self.supported_modes & MODE_SUPPORT_BIT[code] for code, _ in candidates)
        )

    def status(self) -> DriveStatus:
        """Statusword, position and velocity by SDO, and 0x603F when in fault.

        Returns
        -------
        DriveStatus
            The node's state mapped onto the contract's, position and velocity in SI.
        """
        link, sc = self.link, self.scaling
        statusword = int(link.read(0x6041))
        return DriveStatus(
            state=_CONTRACT_STATE.get(state_of(statusword), DriveState.DISABLED),
            position_rad=sc.to_si(Mode.POSITION, int(link.read(0x6064))),
            velocity_rad_s=sc.to_si(Mode.VELOCITY, int(link.read(0x606C))),
            fault_code=int(link.read(0x603F)) if statusword & SW_FAULT else None,
        )

    def enable(self, mode: Mode) -> None:
        """Reset a fault (verified), select ``mode``, then shutdown, switch on, enable.

        Raises
        ------
        DriveFaultError
            The node faulted on the way, or a fault reset did not clear the fault.
        DriveStateError
            A state or the mode was not confirmed within the station's state timeout.
        """
        link = self.link
        link.check()
        link.emcy.clear()
        status = link.tick_until("statusword", lambda sw, m: True)
        if status[0] & SW_FAULT:
            self.reset_fault()
        self.select_mode(mode)
        for word, target in (
            (CW_SHUTDOWN, "READY TO SWITCH ON"),
            (CW_SWITCH_ON, "SWITCHED ON"),
            (CW_ENABLE_OPERATION, "OPERATION ENABLED"),
        ):
            link.controlword = word
            self._await_state(target, allow=("OPERATION ENABLED",) if word == CW_SWITCH_ON else ())
        self.state = DriveState.ENABLED
        log.info("node %d enabled in %s", self.node_id, link.mode.value)

    def _await_state(self, target: str, allow: tuple[str, ...] = ()) -> None:
        def reached(statusword: int, _mode: int) -> bool:
            self.link.raise_if_faulted(statusword, f"while going to {target}")
            return state_of(statusword) in (target, *allow)

        self.link.tick_until(target, reached)

    def reset_fault(self) -> None:
        """Fault reset on a rising edge of bit 7, verified: the fault must clear and stay
        cleared for a few cycles (a reset does not remove the cause).

        Raises
        ------
        DriveFaultError
            The fault did not clear or came back (its code attached).
        """
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
                f"node {self.node_id}: fault reset did not clear the fault ({exc})",
                code=link.fault_code() or code,
            ) from exc
        finally:
            link.controlword = CW_DISABLE_VOLTAGE
        link.emcy.clear()
        log.info("node %d: fault 0x%04X reset", self.node_id, code)

    def select_mode(self, mode: Mode) -> None:
        """Pick the cyclic synchronous mode (else the profile mode) and verify 0x6061.

        Raises
        ------
        DriveStateError
            The node offers no such mode, or 0x6061 does not show it.
        """
        link = self.link
        for code, name in MODE_CANDIDATES[mode]:  # noqa: B007 (used after the loop)
            if self.supported_modes & MODE_SUPPORT_BIT[code]:
                break
        else:
            raise DriveStateError(f"node {self.node_id} supports no {mode.value} mode")
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
            raise DriveStateError(f"node {self.node_id}: 0x6061 does not show mode {code}")
        self.mode_code = code
        log.info("node %d: mode %s", self.node_id, name)

    def disable(self) -> None:
        """Shutdown, confirmed by the statusword; on failure, disable voltage best effort."""
        if not self.link.connected:
            self.state = DriveState.DISABLED
            return
        try:
            self.link.controlword = CW_SHUTDOWN
            self.link.check()
            status = self.link.tick_until(
                "disable",
                lambda sw, m: state_of(sw) in ("READY TO SWITCH ON", "SWITCH ON DISABLED", "FAULT"),
            )
            if self.state is not DriveState.DISABLED:
                log.info("node %d disabled (%s)", self.node_id, state_of(status[0]))
        except DriveError as exc:
            log.error("node %d: disable not confirmed: %s", self.node_id, exc)
            self._best_effort(CW_DISABLE_VOLTAGE)
        self.state = DriveState.DISABLED

    def quick_stop(self) -> None:
        """Quick stop, confirmed when the axis is at rest (or the node left the enabled
        states) within ``quick_stop_timeout_s``; otherwise quick stop best effort."""
        if not self.link.connected:
            return
        link = self.link
        link.controlword = CW_QUICK_STOP
        try:
            link.check()
            deadline = time.monotonic() + self.quick_stop_timeout_s
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
            log.info("node %d quick-stopped (%s)", self.node_id, state)
        except DriveError as exc:
            log.error("node %d: quick stop not confirmed: %s", self.node_id, exc)
            self._best_effort(CW_QUICK_STOP)
        self.state = DriveState.QUICK_STOPPED

    def make_safe(self, error: DriveError) -> None:
        """After a failed run: a faulted node is powered off (it already is in FAULT);
        otherwise quick stop, then disable."""
        if isinstance(error, DriveFaultError):
            self.state = DriveState.FAULT
            self.link.controlword = CW_DISABLE_VOLTAGE
            try:
                self.link.tick()
            except DriveError as exc:
                log.error("node %d: %s", self.node_id, exc)
            return
        self.quick_stop()
        self.disable()

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
            log.warning("node %d now %s", self.node_id, state_of(int(link.read(0x6041))))
        except DriveError as exc:
            log.error("node %d: cannot confirm a safe state: %s", self.node_id, exc)
