"""The ``[firmware]`` table: parsed, validated, refused where it used to live, and every key
obeyed by the simulated drive (the emulators: tests/drives/test_firmware_emulators.py)."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from hil.drives.sim import SimDrive
from hil.errors import ProfileError
from hil.motion import CompensationTable, Excitation, Mode, PositionHarmonic
from hil.profile import builtin_profile_path, load_profile
from plant_sim.firmware import FIRMWARE_KEYS, Firmware
from plant_sim.model import Plant
from plant_sim.params import Harmonic, PlantParams

PROFILE = load_profile()
FS = 4000.0
RIGID = PlantParams(inertia_kg_m2=0.0036, viscous_nm_s_rad=0.005, coulomb_nm=0.02,
                    exact_torque_hold=True)


def _write(tmp_path: Path, edit: dict[str, dict[str, object]], drop: str | None = None) -> Path:
    document = tomllib.loads(builtin_profile_path().read_text(encoding="utf-8"))
    if drop:
        del document[drop]
    for table, values in edit.items():
        document.setdefault(table, {}).update(values)
    path = tmp_path / "unit.toml"
    path.write_text(tomli_w.dumps(document), encoding="utf-8")
    return path


def test_every_shipped_profile_has_the_whole_firmware_table() -> None:
    for name in ("demo_gimbal_elevation", "demo_gimbal_azimuth"):
        raw = tomllib.loads(builtin_profile_path(name).read_text(encoding="utf-8"))
        assert set(raw["firmware"]) == set(FIRMWARE_KEYS)
        assert not set(raw["plant"]) & set(FIRMWARE_KEYS)
        firmware = load_profile(name).firmware
        assert firmware.version == raw["firmware"]["version"]
        assert firmware.velocity_kp_nm_s_rad == raw["firmware"]["velocity_kp_nm_s_rad"]
        assert firmware.feedforward is raw["firmware"]["feedforward"]


@pytest.mark.parametrize(("key", "value", "message"), [
    ("velocity_kp_nm_s_rad", -0.1, "'velocity_kp_nm_s_rad' must be finite and >= 0"),
    ("command_delay_samples", 1.5, "'command_delay_samples': must be an integer"),
    ("command_delay_samples", 65, "'command_delay_samples' must be 0..64"),
    ("feedforward", 1, "'feedforward': must be true or false"),
    ("version", "", "'version' must not be empty"),
    ("velocity_filtr_hz", 300.0, "did you mean 'velocity_filter_hz'"),
])
def test_a_bad_firmware_setting_is_one_error_naming_file_table_and_key(
    tmp_path: Path, key: str, value: object, message: str
) -> None:
    path = _write(tmp_path, {"firmware": {key: value}})
    with pytest.raises(ProfileError, match="firmware") as caught:
        load_profile(path)
    assert message in str(caught.value)
    assert str(path) in str(caught.value)


@pytest.mark.parametrize("key", ["velocity_kp_nm_s_rad", "current_loop_time_constant_s",
                                 "command_delay_samples"])
def test_an_old_profile_with_firmware_keys_in_plant_is_told_where_they_moved(
    tmp_path: Path, key: str
) -> None:
    path = _write(tmp_path, {"plant": {key: PROFILE.raw["firmware"][key]}}, drop="firmware")
    with pytest.raises(ProfileError) as caught:
        load_profile(path)
    text = str(caught.value)
    assert f"[plant] holds '{key}'" in text
    assert "moved to the [firmware] table" in text
    assert str(path) in text
    assert "\n" not in text


def test_the_old_profile_error_is_one_line_from_the_command_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from hil.cli import main

    path = _write(tmp_path, {"plant": {"velocity_ki_nm_rad": 12.0}}, drop="firmware")
    code = main(["simulate", "--profile", str(path), "--duration", "1",
                 "--out", str(tmp_path / "r.csv")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1
    assert "[firmware]" in err


def _torque_run(firmware: Firmware, command: np.ndarray,
                offset: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    trace = Plant(RIGID, firmware=firmware, fs_hz=FS, seed=0).run(Mode.TORQUE, command, offset)
    return trace.position_rad, trace.torque_nm


@pytest.mark.parametrize("delay", [1, 3])
def test_command_delay_shifts_the_response_by_exactly_n_samples(delay: int) -> None:
    command = np.concatenate([np.zeros(5), 0.05 * np.sin(np.arange(2000) / 40.0)])
    plain, torque = _torque_run(Firmware(), command)
    delayed, torque_delayed = _torque_run(Firmware(command_delay_samples=delay), command)
    np.testing.assert_array_equal(delayed[delay:], plain[:-delay])
    np.testing.assert_array_equal(torque_delayed, torque)  # the drive reports its command


def test_velocity_gains_set_the_first_torque_of_a_velocity_step() -> None:
    for kp, ki in ((0.45, 12.0), (0.2, 30.0)):
        firmware = Firmware(velocity_kp_nm_s_rad=kp, velocity_ki_nm_rad=ki)
        trace = Plant(RIGID, firmware=firmware, fs_hz=FS, seed=0).run(
            Mode.VELOCITY, np.full(3, 0.5))
        assert trace.torque_nm[0] == pytest.approx(kp * 0.5 + ki * 0.5 / FS, rel=1e-12)


def test_velocity_filter_is_the_first_order_recursion_of_the_raw_difference() -> None:
    firmware = Firmware(velocity_filter_hz=150.0)
    trace = Plant(RIGID, firmware=firmware, fs_hz=FS, seed=0).run(Mode.TORQUE,
                                                                  np.full(400, 0.05))
    raw = np.diff(trace.position_rad, prepend=0.0) * FS
    gain = 1 - math.exp(-2 * math.pi * 150.0 / FS)
    expected = np.zeros_like(raw)
    for k in range(1, len(raw)):
        expected[k] = expected[k - 1] + gain * (raw[k] - expected[k - 1])
    np.testing.assert_allclose(trace.velocity_rad_s, expected, rtol=1e-9, atol=1e-12)


def test_current_loop_time_constant_is_the_lag_of_the_current() -> None:
    tau = 5e-4
    trace = Plant(RIGID, firmware=Firmware(current_loop_time_constant_s=tau), fs_hz=FS,
                  seed=0).run(Mode.TORQUE, np.full(40, 0.05))
    k = np.arange(40)
    np.testing.assert_allclose(trace.current_a * 0.1, 0.05 * (1 - np.exp(-k / FS / tau)),
                               rtol=1e-9, atol=1e-15)


def test_feedforward_adds_the_torque_offset_only_when_the_firmware_has_it() -> None:
    command = np.full(100, 0.01)
    offset = np.linspace(0.0, 0.02, 100)
    _, on = _torque_run(Firmware(feedforward=True), command, offset)
    _, off = _torque_run(Firmware(feedforward=False), command, offset)
    np.testing.assert_allclose(on, command + offset)
    np.testing.assert_array_equal(off, command)


def _ripple(firmware: Firmware, table: CompensationTable | None) -> float:
    """Position ripple at order 24 of a constant-velocity pass (µrad)."""
    plant = RIGID.with_changes(cogging=(Harmonic(order=24, amplitude=0.004, phase_rad=0.4),))
    drive = SimDrive(plant, firmware=firmware, limits=PROFILE.limits, fs_hz=FS, seed=0)
    drive.enable()
    drive.load_compensation(table)
    rec = drive.run(Excitation(name="pass", mode=Mode.VELOCITY, fs_hz=FS,
                               command=np.full(8000, 0.5)))
    theta, t = rec.position[2000:], rec.time_s[2000:]
    design = np.column_stack([np.ones_like(t), t, t**2, np.sin(24 * theta), np.cos(24 * theta)])
    coef = np.linalg.lstsq(design, theta, rcond=None)[0]
    return float(math.hypot(coef[3], coef[4]) * 1e6)


def test_cogging_compensation_applies_the_loaded_table_only_when_the_firmware_has_it() -> None:
    table = CompensationTable(cogging_nm=(PositionHarmonic(order=24, amplitude=0.004,
                                                           phase_rad=0.4),))
    gains = {"velocity_kp_nm_s_rad": 0.45, "velocity_ki_nm_rad": 12.0}
    bare = _ripple(Firmware(cogging_compensation=True, **gains), None)
    compensated = _ripple(Firmware(cogging_compensation=True, **gains), table)
    ignored = _ripple(Firmware(cogging_compensation=False, **gains), table)
    assert bare > 10.0  # the cogging shows in the motion
    assert compensated < 0.01 * bare  # an exact table leaves only the encoder's grid
    assert ignored == bare


def test_the_firmware_version_is_the_drives() -> None:
    assert PROFILE.plant is not None
    drive = SimDrive(PROFILE.plant, firmware=PROFILE.firmware, limits=PROFILE.limits,
                     fs_hz=FS, seed=0)
    assert drive.info.firmware_version == PROFILE.firmware.version


CLOSED_LOOP = ("velocity_loop_frf", "velocity_step", "tracking", "standstill",
               "cogging_compensation")


#: measured mechanics-style but set by the firmware: a slower current loop is worse
FIRMWARE_SET = {"current_loop_time_constant_ms"}


def test_every_closed_loop_measurement_declares_its_direction() -> None:
    import importlib

    for name in ("demo_gimbal_elevation", "demo_gimbal_azimuth"):
        profile = load_profile(name)
        closed = {m for p in CLOSED_LOOP
                  for m in importlib.import_module(f"hil.suite.{p}").MEASUREMENTS}
        for spec in profile.measurements.values():
            if spec.name in closed | FIRMWARE_SET:
                assert spec.direction in ("higher", "lower"), spec.name
            else:  # mechanics: no better direction
                assert spec.direction is None, spec.name
        assert closed <= set(profile.measurements)


def test_a_direction_other_than_higher_or_lower_is_refused(tmp_path: Path) -> None:
    path = _write(tmp_path, {"measurements": {"inertia_kg_m2": {
        "unit": "kg·m²", "nominal": 0.0036, "tolerance_pct": 15, "direction": "up"}}})
    with pytest.raises(ProfileError, match=r"\[measurements.inertia_kg_m2\] 'direction': "
                                           "must be one of higher, lower"):
        load_profile(path)
