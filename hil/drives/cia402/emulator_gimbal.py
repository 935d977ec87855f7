"""A gimbal's two CiA 402 emulators as one coupled plant: the azimuth node (outer) and the
elevation node (inner) on one bus connection, stepped together at each SYNC through
:class:`plant_sim.gimbal.GimbalPlant` (the inner gimbal's products of inertia, its
imbalance and the azimuth's J across elevation act between them as on the simulator).

Each node keeps its own object dictionary, state machine, PDOs and recorder; the SYNC
runs their phases around one step of both axes: both latch (their RPDO data, received
before the SYNC on the one connection, applied), both give their command for the period,
the gimbal moves, both finish and answer. The SYNC period is the one the host wrote to a
node's 0x1006 (the node under test's; a held node has none), both nodes stepping it.
"""

from __future__ import annotations

import copy
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager

import canopen
import numpy as np

from hil.drives.cia402.emulator import Cia402Emulator
from hil.motion import Mode
from plant_sim.gimbal import AxisBlock, GimbalPlant


class CoupledSync:
    """The SYNC handler of a gimbal's ``outer`` (azimuth) and ``inner`` (elevation) node,
    which share one network (set before they start)."""

    def __init__(self, outer: Cia402Emulator, inner: Cia402Emulator) -> None:
        self.outer, self.inner = outer, inner
        self.plant = GimbalPlant(outer.plant, inner.plant)
        # the two-axis kernel compiles at its first run (seconds, beyond the master's
        # timeouts inside a SYNC): a copy runs it here, the plants untouched
        rest = AxisBlock(mode=Mode.TORQUE, command=np.zeros(1))
        copy.deepcopy(self.plant).run(rest, rest)
        for node in (outer, inner):
            node.coupled = True
            node.sync_handler = self.on_sync

    def on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        """One SYNC of both nodes (the network's receive thread, or a producing node's)."""
        nodes = (self.outer, self.inner)
        with ExitStack() as held:
            for node in nodes:
                held.enter_context(node.lock)
            operational = [node.latch() for node in nodes]
            steps, ramp = self._grid()
            blocks = []
            for node in nodes:
                mode, command, offset = node.block(steps, ramp)
                blocks.append(AxisBlock(mode=mode, command=command, torque_offset=offset))
            traces = self.plant.run(*blocks)
            for node, trace in zip(nodes, traces, strict=True):
                node.finish(trace, steps)
            for node, answer in zip(nodes, operational, strict=True):
                node.publish(answer)

    def _grid(self) -> tuple[int, np.ndarray]:
        """The SYNC period of the node whose 0x1006 the host set (the outer's if both or
        neither did): control periods per SYNC and their interpolation ramp."""
        timed = [node for node in (self.outer, self.inner) if node.period_set]
        return (timed[0] if timed else self.outer).grid()


@contextmanager
def shared_network(*, interface: str, channel: str) -> Iterator[canopen.Network]:
    """The one bus connection a gimbal's emulated nodes share (closed on leaving)."""
    network = canopen.Network()
    network.connect(interface=interface, channel=channel, bitrate=1_000_000)
    try:
        yield network
    finally:
        network.disconnect()


def couple(nodes: dict[str, Cia402Emulator], network: canopen.Network | None
           ) -> CoupledSync | None:
    """The azimuth and elevation nodes among ``nodes`` (by axis) coupled on ``network``
    before they start, or ``None`` when the bus carries no such pair."""
    outer, inner = nodes.get("azimuth"), nodes.get("elevation")
    if outer is None or inner is None or network is None:
        return None
    coupled = CoupledSync(outer, inner)
    network.subscribe(0x80, coupled.on_sync)
    return coupled
