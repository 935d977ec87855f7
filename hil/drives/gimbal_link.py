"""An axis's end of a shared simulated gimbal (:mod:`hil.drives.shared_gimbal`): the
simulated drive of one axis, in its own calibration process, moves the one two-axis plant
the other axis's calibration moves too. Every call waits for the server's answer; a run
returns when the plant's virtual clock has reached its end, whatever the other axis did
meanwhile (it ran its own protocol beside this one, or stood held by its drive)."""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from multiprocessing.connection import Client, Connection

import numpy as np

from hil.beside import Planned
from hil.errors import DriveStateError
from plant_sim.firmware import Firmware
from plant_sim.gimbal import AxisBlock
from plant_sim.model import PlantTrace
from plant_sim.params import Harmonic, PlantParams

#: the environment variable that carries the server's key (hex) to the axes' processes
KEY_VARIABLE = "GIMBAL_HIL_LINK_KEY"


@dataclass(frozen=True, slots=True, kw_only=True)
class AxisHello:
    """What an axis tells the server when it connects: its plant, and its protocols in
    run order (the server plans which run at the same time from them)."""

    axis: str
    plant: PlantParams
    firmware: Firmware
    fs_hz: float
    seed: int
    protocols: tuple[Planned, ...]
    #: where this axis's protocols need the other axis held (``None``: anywhere)
    holds_other_at_rad: float | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class AxisState:
    position_rad: float
    velocity_rad_s: float
    other_position_rad: float


class GimbalLink:
    """The connection of one axis to the shared gimbal's server."""

    def __init__(self, address: str, hello: AxisHello, *, key: bytes | None = None) -> None:
        """Connect and wait until every axis has (the plant is built from their hellos).

        Raises
        ------
        DriveStateError
            No server at ``address``, or the server refused this axis.
        """
        if key is None:
            key = bytes.fromhex(os.environ.get(KEY_VARIABLE, ""))
        try:
            self._conn: Connection = Client(address, family="AF_UNIX", authkey=key)
        except (OSError, EOFError) as exc:
            raise DriveStateError(f"no shared gimbal at {address}: {exc}") from exc
        self.axis = hello.axis
        self._ask("hello", hello)

    def _ask(self, *message: object) -> tuple[object, ...]:
        try:
            self._conn.send(message)
            answer: tuple[object, ...] = self._conn.recv()
        except (OSError, EOFError) as exc:
            raise DriveStateError(f"the shared gimbal went away ({message[0]}): {exc}") from exc
        if answer[0] == "error":
            raise DriveStateError(f"the shared gimbal refused {message[0]}: {answer[1]}")
        return answer

    def begin(self, protocol: str) -> None:
        """Wait until ``protocol`` may start beside what the other axis runs."""
        self._ask("begin", protocol)

    def end(self) -> None:
        """The protocol begun last has ended: the axis stands, held by its drive."""
        self._ask("end")

    def run(self, block: AxisBlock,
            other_path_rad: np.ndarray | None = None) -> tuple[PlantTrace, PlantTrace | None]:
        """This axis through ``block``; with ``other_path_rad`` the other axis follows it in
        position mode (its trace second), else it does what its own calibration says."""
        answer = self._ask("run", block, other_path_rad)
        mine, other = answer[1], answer[2]
        assert isinstance(mine, PlantTrace)
        assert other is None or isinstance(other, PlantTrace)
        return mine, other

    def state(self) -> AxisState:
        answer = self._ask("state")
        assert isinstance(answer[1], AxisState)
        return answer[1]

    def set_locked_rotor(self, locked: bool) -> None:
        self._ask("locked", locked)

    def load_compensation(self, cogging: tuple[Harmonic, ...],
                          kt_ripple: tuple[Harmonic, ...] = ()) -> None:
        self._ask("compensation", cogging, kt_ripple)

    def hold(self) -> None:
        self._ask("hold")

    def close(self) -> None:
        """This axis is done: it stands held from now on. Closing twice does nothing."""
        if self._conn.closed:
            return
        with contextlib.suppress(DriveStateError):  # a server gone already needs no bye
            self._ask("bye")
        self._conn.close()
