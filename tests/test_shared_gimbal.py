"""Two axes' calibrations on one shared simulated gimbal (issue 27, cycle time): an axis
records on it what it records on its own simulation when the other stands; protocols run
beside each other only where neither disturbs the other; the result does not depend on
how fast either process is."""

from __future__ import annotations

import random
import re
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import AbstractContextManager, nullcontext
from pathlib import Path

import numpy as np
import pytest

from hil.beside import ALONE, Beside, Planned, together
from hil.drives.base import Drive
from hil.drives.connect import open_drive
from hil.drives.gimbal_link import KEY_VARIABLE
from hil.drives.shared_gimbal import SharedGimbal
from hil.errors import DriveStateError, InputError, ProfileError
from hil.gimbal.profile import load_gimbal_profile
from hil.gimbal.run import calibrate_gimbal
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile, load_profile
from hil.recording import Recording

AZIMUTH = load_profile("demo_gimbal_azimuth")
ELEVATION = load_profile("demo_gimbal_elevation")
CLAMPED = Beside(still=True)
INDIFFERENT = Beside(indifferent=True)


def _sine(profile: UnitProfile, name: str, seconds: float, hz: float = 2.0) -> Excitation:
    fs = profile.sample_rate_hz
    t = np.arange(round(seconds * fs)) / fs
    return Excitation(name=name, mode=Mode.VELOCITY, fs_hz=fs,
                      command=0.3 * np.sin(2 * np.pi * hz * t))


@pytest.fixture
def server(monkeypatch: pytest.MonkeyPatch) -> Iterator[SharedGimbal]:
    shared = SharedGimbal().start()
    monkeypatch.setenv(KEY_VARIABLE, shared.key.hex())
    try:
        yield shared
    finally:
        shared.close()
    assert shared.error is None


def _linked(profile: UnitProfile, other: UnitProfile, address: str,
            protocols: Sequence[Planned] = ()) -> AbstractContextManager[Drive]:
    return open_drive("sim", profile=profile, unit_serial="SIM-0001",
                      gimbal_axes={other.axis: other}, gimbal_link=address,
                      protocols=tuple(protocols))


def _stand(profile: UnitProfile, other: UnitProfile, address: str) -> None:
    with _linked(profile, other, address):
        pass  # connected, and gone: the axis stands held


def _in_thread(work: Callable[[], object]) -> tuple[threading.Thread, list[object]]:
    found: list[object] = []

    def target() -> None:
        try:
            found.append(work())
        except BaseException as exc:  # the test reads it
            found.append(exc)

    thread = threading.Thread(target=target)
    thread.start()
    return thread, found


def _azimuth_session(drive: Drive) -> list[Recording]:
    drive.enable()
    drive.begin_protocol("first")
    recordings = [drive.run(_sine(AZIMUTH, "a", 0.5))]
    drive.set_elevation(0.6)
    recordings.append(drive.run(_sine(AZIMUTH, "b", 0.5, hz=3.0)))
    drive.end_protocol()
    return recordings


def test_an_axis_records_on_the_shared_gimbal_what_it_records_alone(
        server: SharedGimbal) -> None:
    with open_drive("sim", profile=AZIMUTH, unit_serial="SIM-0001",
                    gimbal_axes={"elevation": ELEVATION}) as alone:
        expected = _azimuth_session(alone)
    # the elevation's calibration connects and leaves at once: it stands held throughout
    thread, left = _in_thread(lambda: _stand(ELEVATION, AZIMUTH, server.address))
    try:
        with _linked(AZIMUTH, ELEVATION, server.address) as shared:
            got = _azimuth_session(shared)
    finally:
        thread.join()
    assert left == [None]
    for mine, theirs in zip(got, expected, strict=True):
        assert mine.columns.keys() == theirs.columns.keys()
        for name, column in theirs.columns.items():
            np.testing.assert_array_equal(mine.columns[name], column, err_msg=name)
    # the gimbal's clock moved for the azimuth alone (its runs and its elevation move)
    assert server.busy == {"azimuth": round(server.elapsed_s * AZIMUTH.sample_rate_hz),
                           "elevation": 0}


AZ_PROTOCOLS = (Planned(name="p1", motion_s=0.4), Planned(name="clamp", motion_s=0.3,
                                                          beside=CLAMPED),
                Planned(name="p2", motion_s=0.2))
EL_PROTOCOLS = (Planned(name="q1", motion_s=0.1), Planned(name="clamp", motion_s=0.25,
                                                          beside=CLAMPED),
                Planned(name="loop", motion_s=0.15, beside=INDIFFERENT))


def _session(opened: AbstractContextManager[Drive], profile: UnitProfile,
             protocols: Sequence[Planned], pause: Callable[[], None]) -> list[np.ndarray]:
    """Each protocol: begin, two runs of half its planned motion (a pause between; the
    rotor clamped for a still one), end."""
    efforts = []
    with opened as drive:
        drive.enable()
        for index, protocol in enumerate(protocols):
            pause()
            drive.begin_protocol(protocol.name)
            for half in range(2):
                pause()
                sine = _sine(profile, f"{protocol.name}{half}", protocol.motion_s / 2,
                             hz=2.0 + index)
                with drive.locked_rotor() if protocol.beside.still else nullcontext():
                    efforts.append(drive.run(sine).effort)
            drive.end_protocol()
    return efforts


def _both(server: SharedGimbal, pauses: tuple[Callable[[], None], Callable[[], None]]
          ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    thread, found = _in_thread(lambda: _session(
        _linked(ELEVATION, AZIMUTH, server.address, EL_PROTOCOLS), ELEVATION, EL_PROTOCOLS,
        pauses[1]))
    azimuth = _session(_linked(AZIMUTH, ELEVATION, server.address, AZ_PROTOCOLS), AZIMUTH,
                       AZ_PROTOCOLS, pauses[0])
    thread.join()
    (elevation,) = found
    assert isinstance(elevation, list), elevation
    return azimuth, elevation


def test_protocols_run_beside_each_other_only_where_neither_disturbs(
        server: SharedGimbal) -> None:
    _both(server, (lambda: None, lambda: None))
    spans = {(axis, name): (start, end) for axis, name, start, end in server.intervals}
    assert len(spans) == len(AZ_PROTOCOLS) + len(EL_PROTOCOLS)
    kinds = {("azimuth", p.name): p.beside for p in AZ_PROTOCOLS}
    kinds |= {("elevation", p.name): p.beside for p in EL_PROTOCOLS}
    overlapped = set()
    for (axis, name), (start, end) in spans.items():
        for (other, theirs), (their_start, their_end) in spans.items():
            if axis == "azimuth" and other == "elevation" and min(end, their_end) > max(
                    start, their_start):
                assert together(kinds[axis, name], kinds[other, theirs]), (name, theirs)
                overlapped.add((name, theirs))
    assert overlapped == {("clamp", "clamp")}  # the one pair the plan can put together
    # the clock: every axis's motion one after the other, less the shorter clamp (the two
    # overlap); the azimuth's includes the station's moves of the elevation back to level
    fs = AZIMUTH.sample_rate_hz
    own_s = {axis: n / fs for axis, n in server.busy.items()}
    assert own_s["elevation"] == pytest.approx(sum(p.motion_s for p in EL_PROTOCOLS), abs=1e-9)
    assert own_s["azimuth"] > sum(p.motion_s for p in AZ_PROTOCOLS) + 0.2  # a settle at least
    assert server.elapsed_s == pytest.approx(sum(own_s.values()) - 0.25, abs=1e-9)


def test_the_shared_gimbal_does_not_depend_on_how_fast_either_axis_computes(
        monkeypatch: pytest.MonkeyPatch) -> None:
    runs = []
    for seed in (1, 2):
        draw = random.Random(seed)

        def pause(draw: random.Random = draw) -> None:
            time.sleep(draw.uniform(0.0, 0.02))

        shared = SharedGimbal().start()
        monkeypatch.setenv(KEY_VARIABLE, shared.key.hex())
        try:
            runs.append(_both(shared, (pause, lambda: None) if seed == 1
                              else (lambda: None, pause)))
        finally:
            shared.close()
    for first, second in zip(*runs, strict=True):
        for a, b in zip(first, second, strict=True):
            np.testing.assert_array_equal(a, b)


def test_together_is_refused_off_the_simulator_before_anything_starts(tmp_path: Path) -> None:
    gimbal = load_gimbal_profile("demo_gimbal")
    with pytest.raises(InputError, match="--together runs an azimuth and an elevation"):
        calibrate_gimbal(gimbal, serial="GMB-0001", out=tmp_path, store_url="off",
                         options=["--drive", "canopen-emulator"], together=True)
    assert not any(tmp_path.iterdir())


def test_a_protocol_that_moves_the_other_axis_shares_the_gimbal_with_nothing() -> None:
    with pytest.raises(ValueError, match="moves the other axis"):
        Beside(moves_other=True, still=True)
    mover = Beside(moves_other=True)
    assert not together(mover, CLAMPED)
    assert not together(CLAMPED, mover)
    assert together(CLAMPED, CLAMPED)
    assert together(INDIFFERENT, INDIFFERENT)
    # an indifferent protocol still moves its axis: a clamp's sensor feels its reactions
    assert not together(INDIFFERENT, CLAMPED)
    assert not together(INDIFFERENT, ALONE)
    assert not together(ALONE, ALONE)


def test_an_axis_that_never_joins_stops_the_other_before_any_motion(
        server: SharedGimbal) -> None:
    thread, found = _in_thread(lambda: _stand(AZIMUTH, ELEVATION, server.address))
    time.sleep(0.2)  # the azimuth waits for the elevation's hello
    server.gone("elevation")  # its calibration was refused: it never connected
    thread.join(timeout=10)
    (error,) = found
    assert isinstance(error, DriveStateError)
    assert "the elevation calibration ended before it joined the shared gimbal" in str(error)
    assert server.elapsed_s == 0.0


def test_an_azimuth_protocol_finds_the_elevation_where_its_profile_holds_it(
        server: SharedGimbal) -> None:
    """Between its own protocols the elevation is moved back to the angle the azimuth's
    profile holds it at (level) before an azimuth protocol begins: the azimuth is
    calibrated at its stated elevation whatever the elevation did before."""
    def elevation() -> None:
        with _linked(ELEVATION, AZIMUTH, server.address) as drive:
            drive.enable()
            drive.begin_protocol("tilt")
            fs = ELEVATION.sample_rate_hz
            ramp = np.minimum(np.arange(round(0.6 * fs)) / fs, 0.3)  # 1 rad/s, then held
            drive.run(Excitation(name="to 0.3", mode=Mode.POSITION, fs_hz=fs, command=ramp))
            drive.end_protocol()

    thread, found = _in_thread(elevation)
    with _linked(AZIMUTH, ELEVATION, server.address) as drive:
        drive.enable()
        stood = []
        # both ask at once: the azimuth first (axis order), then the elevation, which
        # asked before the azimuth's second
        for protocol in ("first", "second"):
            drive.begin_protocol(protocol)
            stood.append(drive.held_text)  # type: ignore[attr-defined]
            drive.run(_sine(AZIMUTH, protocol, 0.2))
            drive.end_protocol()
    thread.join()
    assert found == [None]
    assert [name for _, name, _, _ in server.intervals] == ["first", "tilt", "second"]
    at = [float(text.removeprefix("elevation (simulated, held by its drive) at ")
                .removesuffix(" rad")) for text in stood]
    assert at == [pytest.approx(0.0, abs=1e-4)] * 2
    fs = AZIMUTH.sample_rate_hz
    assert server.busy["azimuth"] > round(0.4 * fs) + round(0.2 * fs)  # the move was its


def test_a_paced_simulator_cannot_join_a_shared_gimbal(server: SharedGimbal) -> None:
    with pytest.raises(InputError, match="shared gimbal keeps its own virtual clock"), \
            open_drive("sim", profile=AZIMUTH, unit_serial="SIM-0001",
                       gimbal_axes={"elevation": ELEVATION}, gimbal_link=server.address,
                       sim_pace=1.0):
        pass
    server.gone("azimuth")
    server.gone("elevation")


def test_a_pair_the_gimbal_declares_runs_together_with_its_runs_overlapping(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Two mechanical protocols the suite keeps apart run at once when the gimbal profile
    declares them (its own evidence); the clock then moves for both at once."""
    az, el = (Planned(name="sines", motion_s=0.4),), (Planned(name="sweep", motion_s=0.3),)
    shared = SharedGimbal(declared=[("sines", "sweep")]).start()
    monkeypatch.setenv(KEY_VARIABLE, shared.key.hex())
    try:
        thread, found = _in_thread(lambda: _session(
            _linked(ELEVATION, AZIMUTH, shared.address, el), ELEVATION, el, lambda: None))
        _session(_linked(AZIMUTH, ELEVATION, shared.address, az), AZIMUTH, az, lambda: None)
        thread.join()
    finally:
        shared.close()
    assert isinstance(found[0], list)
    assert shared.elapsed_s == pytest.approx(0.4, abs=1e-9)  # the longer one: not 0.7 s
    assert {name for _, name, _, _ in shared.intervals} == {"sines", "sweep"}


def _gimbal_profile(tmp_path: Path, together: str) -> Path:
    path = tmp_path / "gimbal.toml"
    path.write_text('[gimbal]\npart_number = "GMB-2"\n\n'
                    '[axes.azimuth]\nprofile = "demo_gimbal_azimuth"\n\n'
                    '[axes.elevation]\nprofile = "demo_gimbal_elevation"\n\n'
                    f'[together]\nbeside = [{together}]\n', encoding="utf-8")
    return path


def test_a_declared_pair_names_a_protocol_of_each_axis_and_why(tmp_path: Path) -> None:
    good = load_gimbal_profile(_gimbal_profile(tmp_path, (
        '{elevation = "gravity_cable", azimuth = "stribeck", why = "bench_together: 0.1 U"}')))
    (pair,) = good.beside
    assert pair.protocols == (("azimuth", "stribeck"), ("elevation", "gravity_cable"))
    assert pair.why == "bench_together: 0.1 U"
    for text, says in [
        ('{azimuth = "stribeck", elevation = "gravity_cable"}', "lacks 'why'"),
        ('{azimuth = "stribeck", why = "x"}', "a protocol of each of two axes"),
        ('{azimuth = "stribek", elevation = "gravity_cable", why = "x"}',
         "the azimuth profile has no protocol 'stribek'"),
        ('{azimuth = "cross_coupling", elevation = "gravity_cable", why = "x"}',
         "moves the other axis"),
        ('{azimuth = "stribeck", roll = "gravity_cable", why = "x"}', "unknown setting 'roll'"),
    ]:
        with pytest.raises(ProfileError, match=re.escape(says)):
            load_gimbal_profile(_gimbal_profile(tmp_path, text))
