"""The locked-rotor fixture of a field-bus station: the clamp engaged by a drive output,
confirmed by a check move before any current is driven against it, and the shaft torque
transducer read on every run made while it holds."""

from __future__ import annotations

import abc
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager

import numpy as np

from hil.drives.base import Capability, Drive
from hil.drives.equipment import Equipment, LockedRotor
from hil.drives.transducer import TransducerReader
from hil.errors import DriveStateError
from hil.motion import Excitation, Mode

CHECK = "locked_rotor_check"


@contextmanager
def clamped(drive: Drive, equipment: Equipment, reader: TransducerReader, *,
            set_clamp: Callable[[bool], None], rate_hz: float) -> Iterator[None]:
    """The clamp engaged and confirmed; released on leaving.

    Parameters
    ----------
    drive : Drive
        The enabled drive (the check move runs through it).
    equipment : Equipment
        The station's transducer and fixture.
    reader : TransducerReader
        The station's transducer, open (one connection for the drive's session: a
        connection opened and closed per block cost the polled drive 50 ms pauses as the
        amplifier's server tore it down).
    set_clamp : callable
        Engages (``True``) or releases the clamp (the drive's output).
    rate_hz : float
        The check move's sample rate (a rate the drive streams).

    Raises
    ------
    DriveStateError
        The station lacks the fixture or the transducer, or the check move moved the axis
        (the clamp released, nothing else driven).
    """
    fixture = equipment.locked_rotor
    if fixture is None:
        raise DriveStateError(f"the station lacks: {Capability.LOCKED_ROTOR.value}")
    set_clamp(True)
    try:
        check_holds(drive, fixture, rate_hz=rate_hz)
        yield
    finally:
        set_clamp(False)
        reader.stop()


def check_holds(drive: Drive, fixture: LockedRotor, *, rate_hz: float) -> float:
    """Ramp the torque to the fixture's check torque; the axis must not move.

    Returns
    -------
    float
        How far it moved (rad).

    Raises
    ------
    DriveStateError
        It moved more than the fixture's tolerance.
    """
    samples = max(2, round(fixture.check_s * rate_hz))
    ramp = np.linspace(0.0, fixture.check_torque_nm, samples)
    recording = drive.run(Excitation(name=CHECK, mode=Mode.TORQUE, fs_hz=rate_hz,
                                     command=ramp))
    moved = float(np.ptp(recording.columns["position_rad"]))
    if moved > fixture.tolerance_rad:
        raise DriveStateError(
            f"the locked-rotor fixture did not hold: the axis moved {moved:.4g} rad under a "
            f"torque ramp to {fixture.check_torque_nm:g} N·m over {fixture.check_s:g} s "
            f"(tolerance {fixture.tolerance_rad:g} rad; [locked_rotor] output_bit "
            f"{fixture.output_bit})")
    return moved


class ClampedRotor(abc.ABC):
    """A field-bus drive's :meth:`Drive.locked_rotor` from its station's equipment: mixed
    into the backend, which says where the clamp is and at what rate the check runs, and
    reads ``_shaft`` on each run while it is set."""

    _shaft: TransducerReader | None = None  # read on each run while clamped
    _transducer: TransducerReader | None = None  # opened at the first block, kept open

    @abc.abstractmethod
    def _clamp_equipment(self) -> Equipment:
        """The station's transducer and fixture, as this drive can serve them."""

    @abc.abstractmethod
    def _set_clamp(self, engaged: bool) -> None:
        """Engage or release the clamp (the drive's output)."""

    @abc.abstractmethod
    def _check_rate_hz(self) -> float:
        """A rate the drive streams or polls at, for the check move."""

    def _released(self) -> None:  # noqa: B027 - a hook: nothing by default
        """After the block (a backend's own clean-up)."""

    def locked_rotor(self) -> AbstractContextManager[None]:
        """The station's clamp engaged and confirmed by a check move, the shaft torque
        transducer read on each run inside the block.

        Raises
        ------
        DriveStateError
            The station lacks the fixture or the transducer, or the clamp did not hold.
        """
        return self._clamped()

    @contextmanager
    def _clamped(self) -> Iterator[None]:
        assert isinstance(self, Drive)
        equipment = self._clamp_equipment()
        if equipment.torque_transducer is None:
            raise DriveStateError(f"the station lacks: {Capability.TORQUE_SENSOR.value}")
        if self._transducer is None:
            reader = TransducerReader(equipment.torque_transducer)
            reader.open()  # DriveCommunicationError: one line naming it
            self._transducer = reader
        with clamped(self, equipment, self._transducer, set_clamp=self._set_clamp,
                     rate_hz=self._check_rate_hz()):
            self._shaft = self._transducer
            try:
                yield
            finally:
                self._shaft = None
                self._released()

    def _close_transducer(self) -> None:
        """The transducer's connection closed (the backend's close calls it)."""
        reader, self._transducer = self._transducer, None
        if reader is not None:
            reader.close()
