"""A gimbal as the unit (issue 27): ``calibrate --gimbal`` calibrates each axis under the
gimbal's one serial and issues one gimbal certificate whose verdict is the worst of its
axes'; a refused axis stops the gimbal and no gimbal certificate passes without every axis.
The axes here are the demo axes cut to their J/B/T_c protocol (a quick complete run)."""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import signal
import subprocess
from pathlib import Path

import pytest

from hil.calibration import LOCK_NAME, UnitLock
from hil.characterise.processes import run_command
from hil.errors import ProfileError
from hil.gimbal.certificate import AxisOutcome, build, verdict, write
from hil.gimbal.profile import load_gimbal_profile
from tests.calibration_process import RunningCalibration
from tests.helpers import subset_profile

pytestmark = pytest.mark.slow(seconds=40)

SERIAL = "GMB-0042"


def _gimbal(directory: Path, *, elevation_text: str | None = None,
            protocols: tuple[str, ...] = ("inertia_friction",)) -> Path:
    """A two-axis gimbal profile over quick axis profiles (``elevation_text`` replaces the
    elevation axis profile's text)."""
    azimuth = subset_profile(directory, *protocols, base="demo_gimbal_azimuth")
    elevation = subset_profile(directory, *protocols)
    if elevation_text is not None:
        elevation.write_text(elevation_text, encoding="utf-8")
    path = directory / "gimbal.toml"
    path.write_text(f'[gimbal]\npart_number = "GMB-2"\nrevision = "B"\n\n'
                    f'[axes.azimuth]\nprofile = "{azimuth.name}"\n\n'
                    f'[axes.elevation]\nprofile = "{elevation.name}"\n', encoding="utf-8")
    return path


def _calibrate(gimbal: Path, out: Path, *options: str) -> tuple[int, str]:
    done = run_command(["calibrate", "--gimbal", str(gimbal), "--unit-serial", SERIAL,
                        "--out", str(out), *options], timeout_s=600)
    return done.returncode, done.stdout + done.stderr


def test_a_gimbal_is_one_serial_one_certificate_one_verdict(tmp_path: Path) -> None:
    out = tmp_path / "certs"
    code, text = _calibrate(_gimbal(tmp_path), out)
    assert code == 0, text
    folder = out / SERIAL
    issued = json.loads((folder / "gimbal-certificate.json").read_text(encoding="utf-8"))
    assert issued["gimbal"]["serial"] == SERIAL
    assert issued["gimbal"]["part_number"] == "GMB-2"
    assert [a["axis"] for a in issued["axes"]] == ["azimuth", "elevation"]
    assert issued["outcome"] == "PASS"
    for axis in issued["axes"]:
        certificate = folder / axis["certificate"]
        assert hashlib.sha256(certificate.read_bytes()).hexdigest() == axis["certificate_sha256"]
        own = json.loads(certificate.read_text(encoding="utf-8"))
        assert own["unit"]["serial"] == SERIAL
        assert own["unit"]["axis"] == axis["axis"]
        assert {r["parameter"] for r in axis["results"]} == {
            r["parameter"] for r in own["results"]}
        # one two-axis plant on the simulator: the other axis held by its own drive
        other = "elevation" if axis["axis"] == "azimuth" else "azimuth"
        assert {entry["held_axes"] for entry in own["raw_data"]} == {
            f"{other} (simulated, held by its drive) at +0.0000 rad"}
    page = (folder / "gimbal-certificate.html").read_text(encoding="utf-8")
    assert "Axis elevation: <span" in page
    assert "azimuth/GMB-0042/certificate.pdf" in page
    pdf = (folder / "gimbal-certificate.pdf").read_bytes()
    assert pdf.startswith(b"%PDF")
    if shutil.which("pdftotext"):
        shown = subprocess.run(["pdftotext", "-", "-"], input=pdf, capture_output=True,
                               check=True).stdout.decode()
        assert "Axis azimuth: PASS" in shown
        assert "the worst of its 2 axes' verdicts" in shown
    person = (folder / "gimbal-certificate.txt").read_text(encoding="utf-8")
    assert "Verdict: PASS (the worst of its 2 axes)" in person
    # the cycle time: each axis's motion time from its own certificate, one after the other
    times = {a["axis"]: json.loads((folder / a["certificate"]).read_text(encoding="utf-8"))[
        "machine_time"]["motion_time_s"] for a in issued["axes"]}
    cycle = issued["cycle_time"]
    assert cycle["motion_time_s"] == times
    assert cycle["one_after_the_other_s"] == pytest.approx(sum(times.values()))
    assert cycle["ratio_to_slowest"] == pytest.approx(sum(times.values()) / max(times.values()))
    assert re.search(r"Motion time: azimuth \d+\.\d s, elevation \d+\.\d s; one after the "
                     r"other \d+\.\d s, \d\.\d\d × the slowest axis", person)
    assert re.search(r"Moment of inertia +0\.00\d+ ± 0\.0000\d\d +kg·m²", person)
    done = run_command(["results", "units", "--out", str(out)])
    assert re.search(rf"{SERIAL} +GMB-2 rev B: azimuth, elevation +2 ", done.stdout), done.stdout
    verified = run_command(["verify", str(folder)])
    assert verified.returncode == 0, verified.stdout + verified.stderr
    assert verified.stdout.strip().endswith("gimbal-certificate.json: VERIFIED")
    with (folder / issued["axes"][1]["certificate"]).open("a", encoding="utf-8") as edit:
        edit.write(" ")  # one byte more in the elevation axis's record
    tampered = run_command(["verify", str(folder)])
    assert tampered.returncode == 1
    assert "axis elevation: " in tampered.stdout
    assert "(SHA-256 differs)" in tampered.stdout


def test_a_failed_axis_fails_the_gimbal_and_the_other_axis_is_still_calibrated(
    tmp_path: Path
) -> None:
    elevation = subset_profile(tmp_path / "base", "inertia_friction").read_text(encoding="utf-8")
    # the elevation axis's inertia specified far from the unit's: that axis FAILs
    failing = re.sub(r"(\[measurements\.inertia_kg_m2\][^\[]*?nominal = )[0-9.e-]+",
                     r"\g<1>0.0072", elevation)
    assert failing != elevation
    out = tmp_path / "certs"
    code, text = _calibrate(_gimbal(tmp_path, elevation_text=failing), out)
    assert code == 1, text
    issued = json.loads((out / SERIAL / "gimbal-certificate.json").read_text(encoding="utf-8"))
    assert [(a["axis"], a["outcome"]) for a in issued["axes"]] == [
        ("azimuth", "PASS"), ("elevation", "FAIL")]
    assert issued["outcome"] == "FAIL"


def test_a_refused_axis_stops_the_gimbal_and_nothing_passes(tmp_path: Path) -> None:
    """The azimuth axis's folder holds a (passing) certificate of another axis: refused
    before motion (exit 4); the elevation axis is not started; the gimbal certificate says
    ERROR for both, the certificate left there is not taken as this run's."""
    out = tmp_path / "certs"
    held = out / SERIAL / "azimuth" / SERIAL / "certificate.json"
    held.parent.mkdir(parents=True)
    # a passing certificate of another axis: it must not pass for this run's azimuth
    held.write_text(json.dumps({"unit": {"serial": SERIAL, "axis": "roll"}, "outcome": "PASS",
                                "aborted": False, "results": []}), encoding="utf-8")
    code, text = _calibrate(_gimbal(tmp_path), out)
    assert code == 4, text
    assert "Traceback" not in text
    issued = json.loads((out / SERIAL / "gimbal-certificate.json").read_text(encoding="utf-8"))
    assert issued["outcome"] == "ERROR"
    assert [a["outcome"] for a in issued["axes"]] == ["ERROR", "ERROR"]
    assert issued["axes"][1]["note"] == "not started: an earlier axis stopped the gimbal"
    assert issued["cycle_time"] is None  # no motion time stated for an axis never run
    assert not (out / SERIAL / "elevation").exists()


def test_a_gimbal_profile_is_checked_before_any_axis_runs(tmp_path: Path) -> None:
    path = _gimbal(tmp_path)
    swapped = path.read_text(encoding="utf-8").replace("[axes.azimuth]", "[axes.roll]")
    path.write_text(swapped, encoding="utf-8")
    with pytest.raises(ProfileError, match=r"\[axes\.roll\] 'profile': .* calibrates the "
                                           r"'azimuth' axis, not 'roll'"):
        load_gimbal_profile(path)
    path.write_text('[gimbal]\npart_number = "GMB-2"\n', encoding="utf-8")
    with pytest.raises(ProfileError, match=r"at least one \[axes\.NAME\] table"):
        load_gimbal_profile(path)
    assert load_gimbal_profile("demo_gimbal").axes[0].name == "azimuth"


def test_the_verdict_is_the_worst_axis() -> None:
    assert verdict(["PASS", "MARGINAL"]) == "MARGINAL"
    assert verdict(["PASS", "INCOMPLETE", "MARGINAL"]) == "INCOMPLETE"
    assert verdict(["FAIL", "PASS"]) == "FAIL"
    assert verdict(["PASS", "NOT COMPLETED"]) == "NOT COMPLETED"  # unknown: never better
    assert verdict([]) == "ERROR"


def test_an_earlier_gimbal_certificate_moves_to_history(tmp_path: Path) -> None:
    gimbal = load_gimbal_profile("demo_gimbal")
    missing = [AxisOutcome(name=a.name, certificate=None, exit_code=4) for a in gimbal.axes]
    first = build(gimbal, serial=SERIAL, folder=tmp_path, axes=missing)
    write(first, tmp_path)
    (tmp_path / "gimbal-certificate.html").write_text("<html></html>", encoding="utf-8")
    second = build(gimbal, serial=SERIAL, folder=tmp_path, axes=missing)
    write(second, tmp_path)
    kept = tmp_path / "history" / first["certificate_id"]
    assert sorted(p.name for p in kept.iterdir()) == [
        "gimbal-certificate.html", "gimbal-certificate.json", "gimbal-certificate.txt"]
    now = json.loads((tmp_path / "gimbal-certificate.json").read_text(encoding="utf-8"))
    assert now["certificate_id"] == second["certificate_id"]


@pytest.mark.realtime
def test_a_stop_sent_to_the_gimbal_stops_the_running_axis_and_nothing_passes(
    tmp_path: Path
) -> None:
    """SIGTERM to the gimbal's process alone (a line controller stopping it) while the
    azimuth axis moves: passed on to that axis's calibration, which quick-stops, disables
    and writes its aborted certificate; the elevation axis is not started; the gimbal
    certificate says ERROR. Before, the axis ran on to its end with the gimbal gone. The
    gimbal is started as a line controller's script starts a job in the background (SIGINT
    ignored, inherited by the axis): the stop passed on must still reach the axis."""
    out = tmp_path / "out"
    # the demo axes: the simulator is far faster than real time, so a short profile's
    # motion ends before the signal could arrive (test_signals.py waits the same way)
    run = RunningCalibration(tmp_path, ["--gimbal", "demo_gimbal", "--unit-serial", SERIAL,
                                        "--out", str(out)], sigint_ignored=True)
    run.wait_for_console("▶ protocol 2")
    run.wait_for_log(r"sim: running", offset=run.log_size(), timeout_s=60)
    logged = run.log_size()
    code = run.stop_with(signal.SIGTERM)
    assert code != 0, run.console
    assert "Traceback" not in run.console, run.console
    with run.log_file.open("rb") as stream:
        stream.seek(logged)
        after = stream.read().decode("utf-8", "replace")
    # the simulator runs an excitation in one call: the stop lands in one (a quick stop)
    # or, on a loaded machine, in the analysis after it; either way the drive ends disabled
    states = re.findall(r"sim: (quick stop|drive disabled)", after)
    assert states, after
    assert states[-1] == "drive disabled", after
    axis = json.loads((out / SERIAL / "azimuth" / SERIAL / "certificate.json").read_text(
        encoding="utf-8"))
    assert axis["aborted"] is True
    issued = json.loads((out / SERIAL / "gimbal-certificate.json").read_text(encoding="utf-8"))
    assert [a["outcome"] for a in issued["axes"]] == ["ERROR", "ERROR"]
    assert issued["outcome"] == "ERROR"
    assert not (out / SERIAL / "elevation").exists()


def test_a_stop_the_axis_runs_on_past_still_stops_the_gimbal(tmp_path: Path) -> None:
    """An axis process that ignores the stop passed on to it (here a plugin ignores
    SIGINT; a stop lost in the axis is another way) and ends its calibration: the gimbal was
    still told to stop, so the elevation is not started and the gimbal exits interrupted
    (2) with an ERROR certificate. Before, it went on to the next axis."""
    (tmp_path / "runs_on.py").write_text(
        "import signal\n\n\ndef pytest_sessionstart(session):\n"
        "    signal.signal(signal.SIGINT, signal.SIG_IGN)\n", encoding="utf-8")
    out = tmp_path / "out"
    run = RunningCalibration(tmp_path, ["--gimbal", str(_gimbal(tmp_path)), "--unit-serial",
                                        SERIAL, "--out", str(out)],
                             ("-p", "runs_on", "--sim-pace", "1"))  # the stop lands in motion
    run.wait_for_log(r"sim: running", timeout_s=120)
    code = run.stop_with(signal.SIGTERM)
    assert code == 2, run.console
    azimuth = json.loads((out / SERIAL / "azimuth" / SERIAL / "certificate.json").read_text(
        encoding="utf-8"))
    assert azimuth["aborted"] is False  # it ran on to its end
    issued = json.loads((out / SERIAL / "gimbal-certificate.json").read_text(encoding="utf-8"))
    assert issued["outcome"] == "ERROR"
    assert issued["axes"][1]["outcome"] == "ERROR"
    assert not (out / SERIAL / "elevation").exists()


def test_a_second_calibration_of_the_gimbal_at_once_is_refused_before_motion(
        tmp_path: Path) -> None:
    """The gimbal folder is locked for the whole run (the axes lock their own folders
    only): a second ``calibrate --gimbal`` of the serial into the same folder is refused in
    one line naming the holder, no axis starts and no gimbal certificate is written; a
    serial that is no serial is refused before a folder is made."""
    out = tmp_path / "certs"
    held = UnitLock.acquire(out / SERIAL)  # another gimbal calibration, under way
    try:
        code, text = _calibrate(_gimbal(tmp_path), out)
    finally:
        held.release()
    assert code == 2, text
    (line,) = text.strip().splitlines()
    assert "another calibration is writing this unit folder" in line, line
    assert sorted(p.name for p in (out / SERIAL).iterdir()) == [LOCK_NAME]
    done = run_command(["calibrate", "--gimbal", str(_gimbal(tmp_path)), "--unit-serial",
                        "../GMB-0042", "--out", str(out)], timeout_s=600)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "is not a unit serial" in done.stderr
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_dir()) == ["certs"]


def test_the_axes_together_run_a_clamped_rotor_beside_a_clamped_rotor_only(
        tmp_path: Path) -> None:
    """``--together``: both axes' calibrations at once on one shared simulated gimbal; the
    two locked-rotor K_t protocols run beside each other, the mechanical ones one after the
    other; the gimbal certificate states the clock and the pair."""
    out = tmp_path / "certs"
    gimbal = _gimbal(tmp_path, protocols=("inertia_friction", "torque_constant"))
    code, text = _calibrate(gimbal, out, "--together", "--store", "off")
    assert code == 0, text
    assert "azimuth   | " in text  # each line says whose it is
    assert "elevation | " in text
    issued = json.loads((out / SERIAL / "gimbal-certificate.json").read_text(encoding="utf-8"))
    assert issued["outcome"] == "PASS"
    assert [a["outcome"] for a in issued["axes"]] == ["PASS", "PASS"]
    cycle = issued["cycle_time"]
    (pair,) = cycle["beside"]
    assert pair["azimuth"] == pair["elevation"] == "torque_constant"
    assert pair["overlap_s"] > 0
    # the clamped sweeps overlap (each axis's moves between them wait for the other's)
    saved_s = cycle["one_after_the_other_s"] - cycle["together_s"]
    assert 1.0 < saved_s < pair["overlap_s"]
    assert cycle["together_s"] >= max(cycle["own_motion_s"].values())
    txt = (out / SERIAL / "gimbal-certificate.txt").read_text(encoding="utf-8")
    assert "azimuth torque_constant beside elevation torque_constant" in txt


def test_a_stop_sent_to_the_axes_together_stops_both_and_nothing_passes(
        tmp_path: Path) -> None:
    out = tmp_path / "out"
    run = RunningCalibration(tmp_path, ["--gimbal", "demo_gimbal", "--unit-serial", SERIAL,
                                        "--out", str(out), "--together"], sigint_ignored=True)
    run.wait_for_console("▶ protocol 2")
    code = run.stop_with(signal.SIGTERM)
    assert code != 0, run.console
    assert "Traceback" not in run.console, run.console
    issued = json.loads((out / SERIAL / "gimbal-certificate.json").read_text(encoding="utf-8"))
    assert issued["outcome"] == "ERROR"
    for axis in ("azimuth", "elevation"):
        certificate = out / SERIAL / axis / SERIAL / "certificate.json"
        if certificate.exists():  # an axis stopped before its first protocol writes none
            assert json.loads(certificate.read_text(encoding="utf-8"))["outcome"] != "PASS"
