"""The whole elevation suite over the ODrive emulator (lockstep, no wall clock), through
``gimbal-hil calibrate`` as an operator runs it: J/B/T_c judged against the emulated
plant's truth (noise, quantisation and the loops' lag on); the protocols that need more
than the 500 Hz the cyclic messages give skip with the figure; none stops with an error."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from hil.profile import load_profile

pytestmark = pytest.mark.slow

PROFILE = "demo_gimbal_elevation"


@pytest.fixture(scope="module")
def certificate(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    out = tmp_path_factory.mktemp("odrive")
    done = subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--drive", "odrive-emulator",
         "--profile", PROFILE, "--unit-serial", "OD-1", "--out", str(out), "--",
         "--no-documents", "--store", "off"],
        capture_output=True, text=True, timeout=600, check=False, cwd=out,
    )
    path = out / "OD-1" / "certificate.json"
    assert path.is_file(), done.stdout[-3000:] + done.stderr[-3000:]
    document: dict[str, object] = json.loads(path.read_text(encoding="utf-8"))
    return document


@pytest.mark.parametrize("name", ["inertia_kg_m2", "viscous_nm_s_rad", "coulomb_nm"])
def test_j_b_and_coulomb_hold_the_emulated_truth(certificate: dict[str, object],
                                                 name: str) -> None:
    plant = load_profile(PROFILE).plant  # the truth: the test reads it, the harness does not
    assert plant is not None
    gain = 1 + plant.torque_constant_error_rel  # results in reported-torque units
    truth = {"inertia_kg_m2": plant.total_inertia_kg_m2 / gain,
             "viscous_nm_s_rad": plant.viscous_nm_s_rad / gain,
             "coulomb_nm": plant.coulomb_nm / gain}[name]
    found = {r["parameter"]: r for r in certificate["results"]}[name]  # type: ignore[attr-defined]
    assert found["outcome"] == "PASS", found
    assert abs(found["value"] - truth) <= found["expanded_uncertainty"], (name, found)
    if name == "inertia_kg_m2":
        assert found["expanded_uncertainty"] < 0.05 * truth  # resolved


def test_what_the_link_cannot_sample_is_skipped_with_the_figure(
        certificate: dict[str, object]) -> None:
    skipped = {m["protocol"]: m["reason"]  # type: ignore[index]
               for m in certificate["not_measured"]}  # type: ignore[attr-defined]
    assert "needs a sample rate of at least 600 Hz" in skipped["current_loop"]
    assert "needs a sample rate of at least 615.4 Hz" in skipped["cogging"]
    for protocol in ("current_loop", "cogging"):
        assert "the drive offers 500 Hz" in skipped[protocol]
        assert "odrive cansimple virtual" in skipped[protocol]
    stopped = [m for m in certificate["not_measured"]  # type: ignore[attr-defined]
               if not m["reason"].startswith("skipped")]
    assert not stopped, stopped
    drive = certificate["drive"]
    assert drive["kind"] == "odrive-emulator"  # type: ignore[index]
    assert drive["max_sample_rate_hz"] == 500.0  # type: ignore[index]
    assert certificate["conditions"] == {"drive_kind": "odrive-emulator", "simulated": True}
