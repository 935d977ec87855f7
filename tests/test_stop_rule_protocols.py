"""The stop rule on three more protocols (current loop, standstill, Stribeck staircase): a
clean simulated unit stops after one run, a noisy one runs ``max_runs`` and its certificate
says which U was above which target; a protocol that cannot pool refuses the rule.

The noisy unit's plant has 20 × the demo's torque noise; both units leave out the demo's
noise inside the loops (the standstill ripple is made of it: the clean unit would not be
clean). The target, 0.05 of the
half-width, sits between the two units' Us (U over the half-width after one run, clean →
noisy, on the simulator's deterministic seed: τ 0.017 → 0.18, T_s 0.012 → 0.15, torque
ripple 0.023 → 0.29): at least 2 × below the noisy one's even pooled over two runs
(÷ √2), 2.2 × above the clean one's. The noisy Us are the Type A lines, which scale with
the noise; the clean ones are mostly not (quantisation, method). The gravity sweep and the
cogging analysis run too: the staircase takes the cable loop and the K_t ripple table out
of them (on the noisy unit the cable loop's u, a line runs cannot reduce, then dominates
T_s's U, and the rule says so).
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest

from hil.drives.sim import SimDrive
from hil.errors import ProfileError
from hil.profile import builtin_profile_path, load_profile
from hil.suite import cogging
from hil.suite.catalogue import PROTOCOL_OF
from plant_sim.params import LOOP_NOISE_DEFAULTS

pytest_plugins = ["pytester"]

DEMO = "demo_gimbal_elevation"
FRACTION, MAX_RUNS = 0.05, 2
# the staircase takes the cogging protocol's K_t ripple table out (analysed on the gravity
# sweep's passes); without it the method's wider line keeps T_s's U above the target
RIPPLE_TABLE = {"gravity_cable": "", "cogging": ""}
JUDGED = {  # protocol: the result its rule judges
    "current_loop": "current_loop_time_constant_ms",
    "standstill": "standstill_torque_ripple_mnm",
    "stribeck": "static_friction_nm",
}


def _profile(tmp_path: Path, *, noise_scale: float, tables: dict[str, str]) -> Path:
    """The demo profile with only ``tables``' protocols, each table extended by its lines,
    and the plant's torque noise scaled."""
    blocks = []
    for block in re.split(r"(?m)^(?=\[)", builtin_profile_path(DEMO).read_text("utf-8")):
        table = re.match(r"\[protocols\.(\w+)\]", block)
        if table and table.group(1) not in tables:
            continue
        result = re.match(r"\[measurements\.(\w+)\]", block)
        if result and PROTOCOL_OF[result.group(1)] not in tables:
            continue  # a result whose protocol the profile does not configure is refused
        blocks.append(block.rstrip("\n") + "\n" + tables[table.group(1)] + "\n\n"
                      if table else block)
    noise = load_profile(DEMO).plant
    assert noise is not None
    text, found = re.subn(r"(?m)^torque_noise_nm = .*$",
                          f"torque_noise_nm = {noise.torque_noise_nm * noise_scale!r}",
                          "".join(blocks))
    assert found == 1
    for key in LOOP_NOISE_DEFAULTS:
        text = re.sub(rf"(?m)^{key} = .*$", f"{key} = 0.0", text)
    path = tmp_path / "unit.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _certificate(pytester: pytest.Pytester, tmp_path: Path, noise_scale: float,
                 tables: dict[str, str]) -> dict[str, Any]:
    profile = _profile(tmp_path, noise_scale=noise_scale, tables=tables)
    out = tmp_path / "certs"
    # a subprocess, as tests/test_plugin.py: one calibration per interpreter
    pytester.runpytest_subprocess(
        "--pyargs", "gimbal_hil_protocols", "-p", "no:cacheprovider", "--out", str(out),
        "--profile", str(profile), "--store", "off", "--no-documents")
    certificate: dict[str, Any] = json.loads(
        (out / "SIM-0001" / "certificate.json").read_text(encoding="utf-8"))
    return certificate


@pytest.mark.parametrize(("noise_scale", "runs"), [(1.0, 1), (20.0, MAX_RUNS)])
def test_a_clean_unit_runs_once_and_a_noisy_one_until_max_runs_saying_why(
        pytester: pytest.Pytester, tmp_path: Path, noise_scale: float, runs: int) -> None:
    rules = {name: f'stop_at_u_fraction = {FRACTION}\nmax_runs = {MAX_RUNS}\n'
                   f'stop_results = "{result}"' for name, result in JUDGED.items()}
    cert = _certificate(pytester, tmp_path, noise_scale, {**rules, **RIPPLE_TABLE})
    results = {r["parameter"]: r for r in cert["results"]}
    for protocol, judged in JUDGED.items():
        details = cert["method"]["details"][protocol]
        assert details["runs"] == runs, (protocol, details["stop_rule"])
        excitations = [f["excitation"] for f in cert["raw_data"] if f["protocol"] == protocol]
        assert all(excitations.count(e) == runs for e in excitations), excitations
        result = results[judged]
        noise_line = result["budget"][0]
        if runs == 1:
            assert details["stop_rule"] == (
                f"every U ≤ {FRACTION:g} × the tolerance half-width after 1 run")
            assert "mean of" not in noise_line["component"]
            continue
        said = re.fullmatch(rf"max_runs = {MAX_RUNS} reached with {judged} U = (\S+) > (\S+) "
                            rf"{re.escape(result['unit'])}"
                            r"( \(runs cannot take it below \S+: Type B and shared lines\))?",
                            details["stop_rule"])
        assert said, details["stop_rule"]
        u, target = float(said.group(1)), float(said.group(2))
        half_width = (result["upper_limit"] - result["lower_limit"]) / 2
        assert target == pytest.approx(FRACTION * half_width, rel=0.06)  # 2 digits: ≤ 5 %
        assert u == pytest.approx(result["expanded_uncertainty"], rel=0.06)
        assert u > target
        assert noise_line["type"] == "A"
        assert noise_line["component"].endswith(f"mean of {MAX_RUNS} runs")


def test_cogging_analyses_the_first_of_the_gravity_protocols_repeated_sweeps(
        pytester: pytest.Pytester, tmp_path: Path) -> None:
    """The sweep a calibration without the gravity protocol's rule has too: the cogging
    result does not depend on how many times the sweep ran."""
    never = f"stop_at_u_fraction = 1e-6\nmax_runs = {MAX_RUNS}"  # no U reaches it
    cert = _certificate(pytester, tmp_path, 1.0, {"gravity_cable": never, "cogging": ""})
    details = cert["method"]["details"]
    assert details["gravity_cable"]["runs"] == MAX_RUNS
    sweeps = [f["file"] for f in cert["raw_data"] if f["excitation"] == "sweep"]
    assert sweeps == ["recordings/gravity_cable__sweep.csv.gz",
                      "recordings/gravity_cable__sweep__2.csv.gz"]
    assert details["cogging"]["recordings_analysed"] == {"passes": sweeps[0]}


def test_cogging_on_the_gravity_sweeps_passes_refuses_the_rule(tmp_path: Path) -> None:
    """With passes = "gravity_cable" the cogging protocol analyses one recording of another
    protocol: running its analysis again would pool one measurement with itself."""
    text = builtin_profile_path(DEMO).read_text("utf-8")
    assert '[protocols.cogging]\npasses = "gravity_cable"' in text
    for key in LOOP_NOISE_DEFAULTS:
        text = re.sub(rf"(?m)^{key} = .*$", f"{key} = 0.0", text)
    path = tmp_path / "unit.toml"
    path.write_text(text.replace('[protocols.cogging]\n',
                                 '[protocols.cogging]\nstop_at_u_fraction = 0.25\n'), "utf-8")
    profile = load_profile(path)
    assert profile.plant is not None
    with SimDrive(profile.plant, firmware=profile.firmware, limits=profile.limits,
                  fs_hz=profile.sample_rate_hz, seed=1) as drive:
        info = drive.info
    with pytest.raises(ProfileError, match=r"\[protocols\.cogging\] 'stop_at_u_fraction': "
                                           r"no stop rule here: passes = 'gravity_cable'"):
        cogging.Spec.from_profile(profile, info)
    path.write_text(text.replace('[protocols.cogging]\npasses = "gravity_cable"',
                                 '[protocols.cogging]\npasses = "own"\nstop_at_u_fraction = 0.25'),
                    "utf-8")
    assert cogging.Spec.from_profile(load_profile(path), info).stop is not None  # own passes
