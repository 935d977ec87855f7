"""Timing conventions of the CiA 402 stream, pinned by exact tests through real frames, and
the current-loop lag measured over them (the sample instants decide a 0.3 ms lag at 1 kHz).

Row k of a streamed recording is the drive's last control-loop sample before SYNC k: the
position measured at ``t_k − T_c`` and the torque commanded over ``[t_k − T_c, t_k]``; the
target sent before SYNC k is applied at SYNC k (reached at SYNC k+1 when interpolated).
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.drives.cia402.drive import CanOpenDrive
from hil.drives.cia402.emulator import INTERPOLATION_HOLD
from hil.drives.emulated import canopen_emulator
from hil.errors import IdentificationError
from hil.identify.current_loop import CurrentLoopResult, acquisition_path, torque_hold_s
from hil.measurement import load_method_bias, with_method_terms
from hil.motion import Excitation, Mode
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite import current_loop as protocol
from plant_sim.firmware import Firmware
from plant_sim.model import PlantTrace
from plant_sim.params import PlantParams

# the wall clock times its field-bus loops: run alone, not beside other tests (README)
pytestmark = pytest.mark.realtime

J = 0.004
CONTROL_S = 2.5e-4  # the emulator's control period at the demo's 4 kHz
PERIOD_S = 1e-3  # the station's SYNC
LSB_RAD = 2 * math.pi / (1 << 20)  # the emulator's encoder


def _frictionless(profile: UnitProfile) -> UnitProfile:
    plant = PlantParams(inertia_kg_m2=J, torque_limit_nm=0.5, exact_torque_hold=True)
    return dataclasses.replace(profile, plant=plant, firmware=Firmware())


@pytest.mark.parametrize("sampling", ["instantaneous", "mean"])
@pytest.mark.parametrize("interpolation", [0, INTERPOLATION_HOLD])
def test_torque_step_row_and_position_instant(
    profile: UnitProfile, interpolation: int, sampling: str
) -> None:
    """A torque step in CST on a frictionless, lag-free axis: exactly which row shows it,
    and the position of each row is the double integral up to ``t_k − T_c``. With the
    averaged torque (0x2077) row k is the mean of the control-period torques over
    ``[t_k − T_s, t_k]``: the interpolated step's ramp shows as its mean in row k0+1."""
    step_nm, k0 = 0.1, 20
    command = np.where(np.arange(60) >= k0, step_nm, 0.0)
    with (
        canopen_emulator(
            _frictionless(profile),
            seed=0,
            interpolation=interpolation,
            station_changes={"torque_sample": sampling},
        ) as (_emulator, station),
        CanOpenDrive(station, limits=profile.limits) as drive,
    ):
        assert isinstance(drive, CanOpenDrive)
        drive.enable(Mode.TORQUE)
        start = drive.status().position_rad
        recording = drive.run(
            Excitation(name="step", mode=Mode.TORQUE, fs_hz=1000.0, command=command)
        )
    assert recording.metadata["control_period_s"] == f"{CONTROL_S:g}"
    assert recording.metadata["command_interpolation"] == (
        "linear" if interpolation == 0 else "hold"
    )
    assert recording.metadata["torque_sample"] == sampling
    torque = recording.columns["torque_nm"]
    # the command of row k is in the RPDO before SYNC k; the drive reports it at SYNC k+1
    first = step_nm
    if sampling == "mean":
        assert recording.metadata["torque_mean_period_s"] == f"{PERIOD_S:g}"
        if interpolation == 0:  # the mean of the ramp 1/4 … 4/4 over SYNC period k0
            first = step_nm * (1 + 2 + 3 + 4) / 16
    assert np.all(torque[: k0 + 1] == 0.0)
    assert torque[k0 + 1] == pytest.approx(first, abs=1e-12)
    assert np.all(torque[k0 + 2 :] == pytest.approx(step_nm, abs=1e-12))
    position = recording.columns["position_rad"] - start
    t = recording.time_s - recording.time_s[0]
    expected = _step_position(len(t), k0, step_nm, interpolation)
    if interpolation == INTERPOLATION_HOLD:
        closed_form = step_nm / (2 * J) * np.clip(t - CONTROL_S - k0 * PERIOD_S, 0.0, None) ** 2
        assert expected == pytest.approx(closed_form, abs=1e-12)
    assert np.max(np.abs(position - expected)) <= 1.01 * LSB_RAD
    # and not one control period later or earlier: those differ by many counts at the end
    shifted = step_nm / (2 * J) * np.clip(t - k0 * PERIOD_S, 0.0, None) ** 2
    assert np.max(np.abs(position - shifted)) > 20 * LSB_RAD


def _step_position(rows: int, k0: int, step_nm: float, interpolation: int) -> np.ndarray:
    """The position of each row (from the run's start) under a torque step at SYNC k0 on
    the frictionless axis: the exact double integral of the torque per control period n
    (4 per SYNC), the step from SYNC k0 on, or a ramp to it over [t_k0, t_k0+1] when
    interpolated; row k measured at the start of control period 4k - 1 (t_k - T_c)."""
    fine = np.where(np.arange(4 * rows) >= 4 * k0, step_nm, 0.0)
    if interpolation == 0:
        fine[4 * k0 : 4 * k0 + 4] = step_nm * np.arange(1, 5) / 4
    velocity = np.concatenate([[0.0], np.cumsum(fine) * CONTROL_S / J])
    angle = np.concatenate([[0.0], np.cumsum(velocity[:-1] + velocity[1:]) * CONTROL_S / 2])
    return np.concatenate([[0.0], angle[4 * np.arange(1, rows) - 1]])


def test_late_answer_stays_on_its_sync(profile: UnitProfile) -> None:
    """The emulator answers one SYNC of a lockstep run later than the PDO timeout (a loaded
    host descheduling it; here a sleep at that SYNC, 3 × the timeout): its TPDOs are still
    filed under that SYNC, and no row after it carries the previous SYNC's feedback (they
    were all one SYNC late: positions off by many counts)."""
    step_nm, k0 = 0.1, 20
    pdo_timeout_s = 0.02
    command = np.where(np.arange(60) >= k0, step_nm, 0.0)
    with (
        canopen_emulator(
            _frictionless(profile),
            seed=0,
            station_changes={"torque_sample": "instantaneous", "pdo_timeout_s": pdo_timeout_s},
        ) as (emulator, station),
        CanOpenDrive(station, limits=profile.limits) as drive,
    ):
        drive.enable(Mode.TORQUE)
        start = drive.status().position_rad
        late_sync = emulator.sync_count + k0 + 10  # the run's SYNC k0 + 10 (counted from 1)
        finish = emulator.finish

        def late_finish(trace: PlantTrace, steps: int) -> None:  # the receive thread's SYNC
            if emulator.sync_count == late_sync:
                time.sleep(3 * pdo_timeout_s)
            finish(trace, steps)

        emulator.finish = late_finish  # type: ignore[method-assign]
        recording = drive.run(
            Excitation(name="step", mode=Mode.TORQUE, fs_hz=1000.0, command=command)
        )
    assert recording.metadata["lost_samples"] == "0"  # the late answer was collected
    expected = _step_position(len(command), k0, step_nm, interpolation=0)
    position = recording.columns["position_rad"] - start
    assert np.max(np.abs(position - expected)) <= 1.01 * LSB_RAD


def _lagged(profile: UnitProfile, tau_s: float) -> UnitProfile:
    assert profile.plant is not None
    return dataclasses.replace(
        profile, firmware=profile.firmware.with_changes(current_loop_time_constant_s=tau_s)
    )


def _current_loop_over_canopen(
    profile: UnitProfile, *, seed: int, interpolation: int = 0, sampling: str = "instantaneous"
) -> CurrentLoopResult:
    recording, spec = _sines_over_canopen(profile, seed=seed, interpolation=interpolation,
                                          sampling=sampling)
    assert spec.fs_hz == pytest.approx(1000.0)
    hold = torque_hold_s(recording.metadata, fs_hz=spec.fs_hz)
    assert hold.hold_s == pytest.approx(CONTROL_S)
    assert hold.mean_samples == (4 if sampling == "mean" else 1)
    return protocol.analyse(recording, spec)


def _sines_over_canopen(profile: UnitProfile, *, seed: int, sampling: str,
                        interpolation: int = 0) -> tuple[Recording, protocol.Spec]:
    """The current-loop protocol's sines streamed at 1 kHz from the emulator, and its spec."""
    with (
        canopen_emulator(
            profile,
            seed=seed,
            interpolation=interpolation,
            station_changes={"torque_sample": sampling},
        ) as (_emu, station),
        CanOpenDrive(station, limits=profile.limits) as drive,
    ):
        drive.enable()
        spec = protocol.Spec.from_profile(profile, drive.info)
        move, sines = protocol.excitation(spec, position_rad=drive.status().position_rad)
        drive.run(move)
        return drive.run(sines), spec


@settings(max_examples=3, deadline=None)
@given(tau_ms=st.floats(0.21, 0.6), seed=st.integers(0, 2**16))
def test_hidden_lag_is_recovered_over_canopen(
    profile: UnitProfile, tau_ms: float, seed: int
) -> None:
    """The demo plant with noise (in the loops too), quantisation, cogging, velocity filter
    on, τ hidden: the 1 kHz SYNC stream with the torque averaged over each SYNC period (the
    default where the drive offers it) measures it within the accuracy the profile claims,
    from the unit's lower limit (0.21 ms) up."""
    accuracy = profile.measurement("current_loop_time_constant_ms").accuracy_rel
    assert accuracy is not None
    result = _current_loop_over_canopen(_lagged(profile, tau_ms * 1e-3), seed=seed,
                                        sampling="mean")
    assert result.time_constant.value == pytest.approx(tau_ms, rel=accuracy)


@pytest.mark.parametrize("sampling", ["instantaneous", "mean"])
def test_a_streamed_lag_is_within_the_uncertainty_the_certificate_states(
    profile: UnitProfile, sampling: str
) -> None:
    """Over a 1 kHz stream the interpolation's images bias τ by the drive's own loop
    (point sample: −3.2 % against U = 2.0 % at 0.3 ms, seed 2, was a strict xfail): the
    certificate states the path's band (fixtures/method_bias_acquisition.toml, built on
    other seeds), not the simulator's line. Over 6 units with τ drawn over the limits its
    ±U holds the truth for at least 5 and error/u has an RMS in 0.5–2 (test_coverage's)."""
    name = "current_loop_time_constant_ms"
    spec_of_result = profile.measurement(name)
    line_map = load_method_bias(axis=profile.axis)
    rng = np.random.default_rng(30)
    held, z = [], []
    for seed in range(6):
        tau_ms = float(rng.uniform(spec_of_result.lower_limit, spec_of_result.upper_limit))
        recording, spec = _sines_over_canopen(_lagged(profile, tau_ms * 1e-3), seed=300 + seed,
                                              sampling=sampling)
        path = acquisition_path(recording.metadata, fs_hz=spec.fs_hz)
        assert path == f"one row per 4 control periods, torque {sampling}"
        line = line_map.line(name, path=path)
        assert line is not None
        estimate = with_method_terms(protocol.analyse(recording, spec).time_constant,
                                     spec_of_result, line)
        assert any(c.source.startswith(f"method: this acquisition path ({path})")
                   for c in estimate.components())
        held.append(abs(estimate.value - tau_ms) <= estimate.expanded_uncertainty)
        z.append((estimate.value - tau_ms) / estimate.standard_uncertainty)
    assert sum(held) >= 5, z
    assert 0.5 <= math.sqrt(np.mean(np.square(z))) <= 2.0, z


def test_held_targets_are_refused(profile: UnitProfile) -> None:
    """A drive that holds each CSV target over the SYNC period: the steps alias into the
    band (τ would come out near 0); the estimator refuses and says why."""
    with pytest.raises(IdentificationError, match="alias"):
        _current_loop_over_canopen(profile, seed=1, interpolation=INTERPOLATION_HOLD)


def test_averaged_torque_lag_at_the_nominal(profile: UnitProfile) -> None:
    """The torque averaged over the SYNC period (0x2077, the default where the drive has it):
    the boxcar model recovers the profile's τ (0.3 ms) within its accuracy (measured
    +0.1 … +0.2 %; the point sample: −3 %)."""
    accuracy = profile.measurement("current_loop_time_constant_ms").accuracy_rel
    assert accuracy is not None
    result = _current_loop_over_canopen(_lagged(profile, 3e-4), seed=7, sampling="mean")
    assert result.time_constant.value == pytest.approx(0.3, rel=accuracy)


def test_averaged_torque_lag_at_the_lower_limit(profile: UnitProfile) -> None:
    """Was +3.5 % (a strict xfail): the simulator's exact-hold correction let the position
    run ahead of the velocity friction sees at constant speed; with that fixed, +0.4 %."""
    accuracy = profile.measurement("current_loop_time_constant_ms").accuracy_rel
    assert accuracy is not None
    result = _current_loop_over_canopen(_lagged(profile, 2.1e-4), seed=0, sampling="mean")
    assert result.time_constant.value == pytest.approx(0.21, rel=accuracy)


def test_a_slower_excitation_is_paced_at_its_own_sync_period(profile: UnitProfile) -> None:
    """Real-time pacing at a quarter of the station's SYNC rate: the drive is told 4 ms
    (0x1006) and the host sends a SYNC every 4 ms, so 0.5 s of excitation takes 0.5 s (it
    took 0.2 s: the SYNCs kept the station's 1 ms while the recording and the drive said
    4 ms). The emulator, in this process, answers some SYNCs late in real time (why its
    station runs in lockstep): lost rows are allowed here, the pace is the subject."""
    changes = {"sync_pacing": "realtime", "lost_sample_fraction": 0.5}
    with (
        canopen_emulator(profile, seed=5, station_changes=changes) as (_, station),
        CanOpenDrive(station, limits=profile.limits) as drive,
    ):
        drive.enable()
        fs_hz = drive.info.max_sample_rate_hz / 4
        excitation = Excitation(name="half_rate", mode=Mode.VELOCITY, fs_hz=fs_hz,
                                command=0.2 * np.sin(2 * math.pi * 2.0 * np.arange(
                                    round(0.5 * fs_hz)) / fs_hz))
        started = time.monotonic()
        recording = drive.run(excitation)
        took_s = time.monotonic() - started
    assert recording.metadata["sync_period_s"] == f"{1 / fs_hz:g}"
    assert 0.9 * excitation.duration_s < took_s < 3 * excitation.duration_s, took_s
    # the SYNCs' own timing is on the recording (issue 28): who produced them, how evenly.
    # How evenly this host sent them is not the subject (a 40 ms stall of CI's runner in a
    # dry run of session 33 put their sd at 4.2 ms, over the period): the figures are there
    # and consistent (what they compute: the next test, on intervals of a known jitter)
    assert recording.metadata["sync_producer"].startswith("host (")
    spread_s = float(recording.metadata["sync_interval_sd_s"])
    largest_s = float(recording.metadata["sync_interval_max_error_s"])
    assert 0 < spread_s <= largest_s < took_s, (spread_s, largest_s, took_s)


def test_the_sync_spread_is_what_the_intervals_show() -> None:
    """Intervals of 4 ms with a known jitter: their standard deviation and largest error."""
    from hil.drives.cia402.acquire import sync_timing

    rng = np.random.default_rng(3)
    error_s = rng.normal(0.0, 2e-4, 500)
    sent_s = list(np.cumsum(np.concatenate([[0.0], 0.004 + error_s])))
    timing = sync_timing(sent_s, 0.004, realtime=True)
    assert float(timing["sync_interval_sd_s"]) == pytest.approx(float(np.std(error_s)), rel=1e-2)
    assert float(timing["sync_interval_max_error_s"]) == pytest.approx(
        float(np.max(np.abs(error_s))), rel=1e-2)
    lockstep = sync_timing(sent_s, 0.004, realtime=False)
    assert "lockstep" in lockstep["sync_producer"]
    assert "sync_interval_sd_s" not in lockstep


@pytest.mark.parametrize(("producer", "named"), [
    ("periodic", "python-can's periodic send"), ("node", "the drive (CiA 301 0x1005")])
def test_a_sync_producer_other_than_the_host_paces_the_run(profile: UnitProfile, producer: str,
                                                          named: str) -> None:
    """The station chooses who sends the SYNC: python-can's periodic send (the kernel's
    broadcast manager on socketcan; on the virtual bus python-can's own thread) or the drive
    itself (0x1005 bit 30). The host counts the SYNCs it sees, the run takes its own
    duration, and the recording names the producer and the spread the frames' own times
    show (issue 28); the drive stops producing when the host leaves."""
    changes = {"sync_pacing": "realtime", "sync_producer": producer,
               "lost_sample_fraction": 0.5}
    with canopen_emulator(profile, seed=5, station_changes=changes) as (emulator, station):
        with CanOpenDrive(station, limits=profile.limits) as drive:
            drive.enable()
            fs_hz = drive.info.max_sample_rate_hz / 4
            excitation = Excitation(name="other_sync", mode=Mode.VELOCITY, fs_hz=fs_hz,
                                    command=0.2 * np.sin(2 * math.pi * 2.0 * np.arange(
                                        round(0.5 * fs_hz)) / fs_hz))
            started = time.monotonic()
            recording = drive.run(excitation)
            took_s = time.monotonic() - started
        syncs = emulator.sync_count
        time.sleep(0.05)
        stopped = emulator.sync_count == syncs
    assert 0.9 * excitation.duration_s < took_s < 3 * excitation.duration_s, took_s
    assert recording.metadata["sync_producer"].startswith(named)
    assert stopped  # no producer left running after the host closed
    spread_s = float(recording.metadata["sync_interval_sd_s"])
    assert 0 < spread_s < 1 / fs_hz, spread_s
    assert len(recording) > 0.5 * len(excitation.command)


def test_a_sync_spread_beyond_the_station_limit_is_refused(profile: UnitProfile) -> None:
    """A station that allows its SYNC intervals a spread no host achieves: the streamed run
    is refused naming the figure and the key, its rows kept on the error."""
    from hil.errors import DriveCommunicationError

    changes = {"sync_pacing": "realtime", "lost_sample_fraction": 0.5,
               "max_sync_interval_sd_s": 1e-9}
    with (
        canopen_emulator(profile, seed=5, station_changes=changes) as (_, station),
        CanOpenDrive(station, limits=profile.limits) as drive,
    ):
        drive.enable()
        fs_hz = drive.info.max_sample_rate_hz / 4
        excitation = Excitation(name="too_uneven", mode=Mode.VELOCITY, fs_hz=fs_hz,
                                command=np.zeros(round(0.2 * fs_hz)))
        with pytest.raises(DriveCommunicationError) as refused:
            drive.run(excitation)
    message = str(refused.value)
    assert "max_sync_interval_sd_s" in message
    assert "'too_uneven'" in message
    assert refused.value.partial_recording is not None
