"""One simulated two-axis gimbal shared by its axes' calibrations, each in a process of its
own (:mod:`hil.drives.gimbal_link` is an axis's end): what lets ``calibrate --gimbal
--together`` run two protocols at the same time.

The plant runs on a virtual clock that moves only while every axis waits on it (for a run,
or for leave to begin its next protocol): what an axis computes between its runs takes no
plant time, so the result does not depend on how fast either process is. An axis that is
not running stands where its drive holds it (position mode), as the other axis of a gimbal
does when the axes are calibrated one after the other.

Which protocols run at the same time is planned from both axes' protocol lists
(:func:`hil.beside.plan_together`): a protocol begins when every protocol the plan puts
before it on the other axis has ended (or was passed over) and it may run beside the one
the other axis is in (:func:`hil.beside.together`, or a pair the gimbal profile declares).
Within such a pair two runs overlap only where neither axis's motion reaches the other's
measurement (clamped beside clamped; a move waits), except in a declared pair. Before an
azimuth protocol an idle elevation is moved to the angle the azimuth's profile holds it at.
"""

from __future__ import annotations

import logging
import secrets
import tempfile
import threading
from collections.abc import Iterable
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, Listener, wait
from pathlib import Path

import numpy as np

from hil.beside import ALONE, Beside, plan_together, together
from hil.drives.gimbal_link import AxisHello, AxisState
from hil.drives.sim import PARTNER_SEED, station_move_rad
from hil.motion import Mode
from plant_sim.gimbal import AxisBlock, GimbalPlant
from plant_sim.model import MotionGuard, Plant, PlantTrace, concatenate_traces

log = logging.getLogger(__name__)

STANDING_RAD = 1e-4  # an idle axis this near its stated angle is not moved there


@dataclass(slots=True)
class _Run:
    block: AxisBlock
    other_path_rad: np.ndarray | None
    asked: int  # its place in the order runs were asked for
    station: str | None = None  # the station's move of this axis, for that axis's protocol
    done: int = 0
    mine: list[PlantTrace] = field(default_factory=list)
    other: list[PlantTrace] = field(default_factory=list)

    @property
    def left(self) -> int:
        return len(self.block.command) - self.done


@dataclass(slots=True)
class _Axis:
    name: str
    conn: Connection | None = None
    hello: AxisHello | None = None
    plant: Plant | None = None
    hold_rad: float = 0.0
    protocol: str | None = None  # the protocol it is in
    waiting: str | None = None  # the protocol it asks to begin
    waiting_since: int = 0  # plant samples
    run: _Run | None = None
    gone: bool = False
    passed: int = 0  # its protocols (in its hello's order) begun or passed over so far
    ended: set[int] = field(default_factory=set)

    @property
    def blocked(self) -> bool:
        """It waits on the plant (or has left): the clock may move."""
        return self.gone or self.waiting is not None or self.run is not None

    def index(self, protocol: str) -> int | None:
        assert self.hello is not None
        names = [p.name for p in self.hello.protocols]
        return names.index(protocol) if protocol in names else None

    def over(self, index: int) -> bool:
        """Its protocol ``index`` has ended, or it went past it without beginning it."""
        current = None if self.protocol is None else self.index(self.protocol)
        return index in self.ended or (index < self.passed and index != current)

    def beside(self, protocol: str | None) -> Beside:
        assert self.hello is not None
        return next((p.beside for p in self.hello.protocols if p.name == protocol), ALONE)


class SharedGimbal:
    """The server: an azimuth (outer) and an elevation (inner), each axis's calibration
    connected over a local socket; run in a thread with :meth:`start`."""

    def __init__(self, outer: str = "azimuth", inner: str = "elevation", *,
                 declared: Iterable[tuple[str, str]] = ()) -> None:
        """``declared``: (outer protocol, inner protocol) pairs the gimbal's profile lets
        run at the same time, their runs overlapping freely (its own evidence that they do
        not disturb each other, :mod:`hil.gimbal.profile`)."""
        self._declared = frozenset(declared)
        self._folder = tempfile.TemporaryDirectory(prefix="gimbal-hil-shared-")
        self.address = str(Path(self._folder.name) / "gimbal.sock")
        self.key = secrets.token_bytes(16)
        self._listener = Listener(self.address, family="AF_UNIX", authkey=self.key)
        self._axes = [_Axis(outer), _Axis(inner)]
        self._gimbal: GimbalPlant | None = None
        self._steps: dict[str, list[int]] = {}  # each axis's protocols → their plan step
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._serve, name="shared-gimbal", daemon=True)
        self.samples = 0  # the virtual clock, in control periods
        self.error: str | None = None
        #: (axis, protocol, first sample, last sample + 1): what ran when
        self.intervals: list[tuple[str, str, int, int]] = []
        #: each axis's own motion (its runs, and the other axis moved by them), in periods
        self.busy = {outer: 0, inner: 0}
        self._began: dict[str, int] = {}
        self._requests = 0

    @property
    def fs_hz(self) -> float:
        """The gimbal's control rate (1.0 before both axes connected)."""
        return 1.0 if self._gimbal is None else self._gimbal.fs_hz

    @property
    def elapsed_s(self) -> float:
        return 0.0 if self._gimbal is None else self.samples / self._gimbal.fs_hz

    def start(self) -> SharedGimbal:
        self._thread.start()
        return self

    def gone(self, axis: str) -> None:
        """``axis``'s process has ended (it may never have connected): it stands held."""
        with self._lock:
            for state in self._axes:
                if state.name == axis:
                    state.gone = True

    def close(self) -> None:
        for state in self._axes:
            state.gone = True
        self._thread.join(timeout=10)
        self._listener.close()
        self._folder.cleanup()

    # -- the server thread ----------------------------------------------------------------
    def _serve(self) -> None:
        pending: list[Connection] = []
        accepting = threading.Thread(target=self._accept, args=(pending,), daemon=True)
        accepting.start()
        try:
            while not all(a.gone for a in self._axes):
                with self._lock:
                    fresh, pending[:] = list(pending), []
                for conn in fresh:
                    self._greet(conn)
                self._refuse_if_alone()
                conns = [a.conn for a in self._axes if a.conn is not None and not a.gone]
                for ready in wait(conns, timeout=0.05) if conns else []:
                    assert isinstance(ready, Connection)
                    self._answer(ready)
                self._advance()
        except Exception as exc:  # reported to both axes and the runner
            log.exception("shared gimbal: stopped")
            self.error = f"{type(exc).__name__}: {exc}"
            for state in self._axes:
                if state.conn is not None and not state.conn.closed:
                    _reply(state.conn, "error", self.error)
                    state.conn.close()

    def _accept(self, pending: list[Connection]) -> None:
        while not all(a.gone for a in self._axes):
            try:
                conn = self._listener.accept()
            except (OSError, EOFError):
                return
            with self._lock:
                pending.append(conn)

    def _greet(self, conn: Connection) -> None:
        """A new connection: an axis's hello (anything else is answered and closed)."""
        if not conn.poll(1.0):
            conn.close()
            return
        try:
            message = conn.recv()
        except (OSError, EOFError):
            conn.close()
            return
        hello = message[1] if message[0] == "hello" else None
        state = next((a for a in self._axes if hello is not None and a.name == hello.axis), None)
        if state is None or state.conn is not None:
            _reply(conn, "error", f"no free axis for {message[0]!r}")
            conn.close()
            return
        state.conn, state.hello = conn, hello
        if all(a.hello is not None for a in self._axes):
            self._build()

    def _refuse_if_alone(self) -> None:
        """An axis ended without joining (its calibration was refused or crashed): the
        gimbal cannot be simulated without its plant, so the axes waiting to start hear why
        (their calibrations stop before any motion)."""
        if self._gimbal is not None:
            return
        missing = [a.name for a in self._axes if a.gone and a.hello is None]
        if not missing:
            return
        for state in self._axes:
            if state.conn is not None and not state.gone:
                _reply(state.conn, "error", f"the {', '.join(missing)} calibration ended "
                                            "before it joined the shared gimbal")
                state.conn.close()
                state.gone = True

    def _build(self) -> None:
        outer, inner = (a.hello for a in self._axes)
        assert outer is not None
        assert inner is not None
        first = Plant(outer.plant, fs_hz=outer.fs_hz, seed=outer.seed, firmware=outer.firmware)
        second = Plant(inner.plant, fs_hz=inner.fs_hz, seed=inner.seed + (PARTNER_SEED << 32),
                       firmware=inner.firmware, initial_position_rad=outer.plant.elevation_rad)
        self._gimbal = GimbalPlant(first, second)
        for state, plant in zip(self._axes, (first, second), strict=True):
            state.plant, state.hold_rad = plant, plant.position_rad
        steps: dict[str, list[int]] = {outer.axis: [0] * len(outer.protocols),
                                       inner.axis: [0] * len(inner.protocols)}
        plan = plan_together(outer.protocols, inner.protocols,
                             lambda a, b: self._beside(a.name, b.name, a.beside, b.beside))
        for number, step in enumerate(plan):
            if step.first is not None:
                steps[outer.axis][step.first] = number
            if step.second is not None:
                steps[inner.axis][step.second] = number
        self._steps = steps
        for state in self._axes:
            assert state.conn is not None
            _reply(state.conn, "ok")

    def _answer(self, conn: Connection) -> None:
        state = next(a for a in self._axes if a.conn is conn)
        try:
            message = conn.recv()
        except (OSError, EOFError):
            state.gone = True
            return
        kind, *args = message
        plant = state.plant
        assert plant is not None
        if kind == "begin":
            state.waiting, state.waiting_since = str(args[0]), self.samples
            return  # answered when granted
        if kind == "run":
            state.run = _Run(block=args[0], other_path_rad=args[1], asked=self._asked())
            return  # answered when the clock reaches its end
        if kind == "end":
            self._end(state)
        elif kind == "state":
            other = self._other(state).plant
            assert other is not None
            _reply(conn, "state", AxisState(position_rad=plant.position_rad,
                                            velocity_rad_s=plant.velocity_rad_s,
                                            other_position_rad=other.position_rad))
            return
        elif kind == "locked":
            plant.set_locked_rotor(bool(args[0]))
        elif kind == "compensation":
            plant.load_compensation(args[0], args[1])
        elif kind == "hold":
            plant.hold()
        elif kind == "bye":  # an answer it no longer waits for is dropped with it
            self._end(state)
            state.gone, state.run, state.waiting = True, None, None
        else:
            _reply(conn, "error", f"unknown request {kind!r}")
            return
        _reply(conn, "ok")

    def _asked(self) -> int:
        self._requests += 1
        return self._requests

    def _other(self, state: _Axis) -> _Axis:
        return self._axes[1] if state is self._axes[0] else self._axes[0]

    def _end(self, state: _Axis) -> None:
        if state.protocol is None:
            return
        index = state.index(state.protocol)
        if index is not None:
            state.ended.add(index)
        self.intervals.append((state.name, state.protocol, self._began.pop(state.name),
                               self.samples))
        state.protocol = None

    # -- the clock ------------------------------------------------------------------------
    def _advance(self) -> None:
        """While every axis waits on the plant: grant a protocol that may begin, else move
        the clock to the end of the shortest run."""
        while self._gimbal is not None and all(a.blocked for a in self._axes) and not all(
                a.gone for a in self._axes):
            if self._grant():
                return
            if not any(a.run is not None for a in self._axes):
                raise RuntimeError("both axes wait for each other: "
                                   + ", ".join(f"{a.name} for {a.waiting}" for a in self._axes))
            self._step()

    def _grant(self) -> bool:
        waiting = sorted((a for a in self._axes if a.waiting is not None and not a.gone),
                         key=lambda a: (a.waiting_since, self._axes.index(a)))
        for state in waiting:
            assert state.waiting is not None
            assert state.conn is not None
            if self._may_begin(state, state.waiting):
                if self._move_other_to_its_angle(state):
                    return False  # the station moves the other axis first: the clock runs
                index = state.index(state.waiting)
                if index is not None:
                    state.passed = max(state.passed, index + 1)
                state.protocol, state.waiting = state.waiting, None
                self._began[state.name] = self.samples
                _reply(state.conn, "go")
                return True
        return False

    def _move_other_to_its_angle(self, state: _Axis) -> bool:
        """Before ``state``'s protocol: the other axis, between protocols of its own, to
        the angle ``state``'s profile holds it at (as its own calibration would find it);
        whether a move was started."""
        other = self._other(state)
        assert state.hello is not None
        assert other.plant is not None
        target = state.hello.holds_other_at_rad
        if (target is None or other.protocol is not None or other.run is not None
                or abs(other.plant.position_rad - target) <= STANDING_RAD):
            return False
        path = station_move_rad(other.plant.position_rad, target, fs_hz=other.plant.fs_hz)
        other.run = _Run(block=AxisBlock(mode=Mode.POSITION, command=path),
                         other_path_rad=None, asked=self._asked(), station=state.name)
        log.info("shared gimbal: %s to %+.4f rad for %s's %s", other.name, target, state.name,
                 state.waiting)
        return True

    def _may_begin(self, state: _Axis, protocol: str) -> bool:
        """``protocol`` may begin on ``state``'s axis now: it may run beside what the other
        axis is in, and every protocol the plan puts before it on the other axis is over."""
        other = self._other(state)
        if other.gone:
            return True
        if other.run is not None and other.run.other_path_rad is not None:
            return False  # the other axis is moving this one
        if other.protocol is not None and not self._beside(
                *self._outer_first((state, protocol), (other, other.protocol))):
            return False
        index = state.index(protocol)
        if index is None:  # not in its plan (it said nothing of it): beside-rule only
            return True
        step = self._steps[state.name][index]
        return all(other.over(j) for j, s in enumerate(self._steps[other.name]) if s < step)

    def _moving(self) -> list[_Axis]:
        """The axes whose runs go now: both, or where one run would disturb the other's
        measurement (a moving axis beside a clamped one whose protocol is not indifferent
        to it), the one started or asked for first; the other stands meanwhile."""
        runs = sorted((a for a in self._axes if a.run is not None),
                      key=lambda a: (a.run.done == 0, a.run.asked))  # type: ignore[union-attr]
        if len(runs) < 2 or self._runs_together(*runs):
            return runs
        return runs[:1]

    def _outer_first(self, one: tuple[_Axis, str], two: tuple[_Axis, str]
                     ) -> tuple[str, str, Beside, Beside]:
        """Two axes' protocols as (outer's, inner's, their declarations)."""
        (a, p), (b, q) = (one, two) if one[0] is self._axes[0] else (two, one)
        return p, q, a.beside(p), b.beside(q)

    def _beside(self, outer: str, inner: str, outer_kind: Beside, inner_kind: Beside) -> bool:
        """Whether the outer's protocol may run beside the inner's: declared by the
        gimbal, or :func:`hil.beside.together`."""
        return (outer, inner) in self._declared or together(outer_kind, inner_kind)

    def _runs_together(self, first: _Axis, second: _Axis) -> bool:
        def moves(state: _Axis) -> bool:
            assert state.plant is not None
            return not state.plant.params.locked_rotor

        def indifferent(state: _Axis) -> bool:
            return state.beside(state.protocol).indifferent

        if any(a.run is not None and (a.run.other_path_rad is not None or a.run.station)
               for a in (first, second)):
            return False
        outer, inner = (first, second) if first is self._axes[0] else (second, first)
        if (outer.protocol, inner.protocol) in self._declared:
            return True  # the gimbal's evidence: their runs overlap freely
        return ((not moves(first) or indifferent(second))
                and (not moves(second) or indifferent(first)))

    def _step(self) -> None:
        assert self._gimbal is not None
        moving = self._moving()
        n = min(a.run.left for a in moving if a.run is not None)
        blocks = [self._block(state, n, moving) for state in self._axes]
        traces = self._gimbal.run(blocks[0], blocks[1])
        done = len(traces[0].time_s)
        self.samples += done
        for state, trace in zip(self._axes, traces, strict=True):
            other = self._other(state)
            if state in moving and state.run is not None:
                self.busy[state.run.station or state.name] += done
                state.run.mine.append(trace)
                state.run.done += done
            elif other in moving and other.run is not None and other.run.other_path_rad is not None:
                other.run.other.append(trace)
        tripped = done < n
        finished = [state for state, trace in zip(self._axes, traces, strict=True)
                    if state in moving and state.run is not None and (state.run.left == 0 or (
                        tripped and _left_guard(state.run.block.guard, trace)))]
        if tripped and not finished:  # stopped, and neither monitor says why: end both
            finished = [state for state in moving if state.run is not None]
        for state in finished:
            assert state.run is not None
            self._finish(state, state.run)

    def _block(self, state: _Axis, n: int, moving: list[_Axis]) -> AxisBlock:
        """What ``state``'s axis does over the next ``n`` periods: its run, the other's
        path for it, or standing where it was left."""
        other = self._other(state)
        if state in moving and state.run is not None:
            run, part = state.run, slice(state.run.done, state.run.done + n)
            offset = run.block.torque_offset
            return AxisBlock(mode=run.block.mode, command=run.block.command[part],
                             torque_offset=None if offset is None or not len(offset)
                             else offset[part], guard=run.block.guard)
        if other in moving and other.run is not None and other.run.other_path_rad is not None:
            path = other.run.other_path_rad[other.run.done:other.run.done + n]
            return AxisBlock(mode=Mode.POSITION, command=path)
        return AxisBlock(mode=Mode.POSITION, command=np.full(n, state.hold_rad))

    def _finish(self, state: _Axis, run: _Run) -> None:
        assert state.conn is not None
        assert state.plant is not None
        mine = concatenate_traces(run.mine)
        other = concatenate_traces(run.other) if run.other_path_rad is not None else None
        if run.block.mode is Mode.POSITION and run.done:
            state.hold_rad = float(run.block.command[run.done - 1])
        else:
            state.hold_rad = state.plant.position_rad
        if run.other_path_rad is not None and run.done:
            self._other(state).hold_rad = float(run.other_path_rad[run.done - 1])
        state.run = None
        if run.station is None:  # the station's own move answers nobody
            _reply(state.conn, "ran", mine, other)


def _left_guard(guard: MotionGuard | None, trace: PlantTrace) -> bool:
    """The trace's last row is outside ``guard`` (its monitor stopped the run)."""
    if guard is None or not len(trace.time_s):
        return False
    position, velocity = trace.position_rad[-1], trace.velocity_rad_s[-1]
    return bool(not guard.position_min_rad <= position <= guard.position_max_rad
                or abs(velocity) > guard.velocity_max_rad_s)


def _reply(conn: Connection, *message: object) -> None:
    try:
        conn.send(message)
    except OSError:
        log.info("shared gimbal: an axis left before its answer")
