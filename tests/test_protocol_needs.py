"""What a protocol takes from an earlier one is declared (issue 25, defect 3): a profile
whose order breaks a need is refused in one line before any motion; a need on a protocol
the profile does not configure runs on the declared fallback, and the certificate says so."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from hil.characterise.processes import run_command
from hil.errors import ProfileError
from hil.profile import load_profile
from hil.suite.catalogue import NEEDS, PROTOCOLS, check_order, check_profile
from tests.helpers import subset_profile


def _moved_last(path: Path, protocol: str) -> Path:
    """The profile with ``[protocols.PROTOCOL]`` moved to the end (after the others)."""
    text = path.read_text(encoding="utf-8")
    table = re.search(rf"^\[protocols\.{protocol}\]\n(?:(?!\[).*\n?)*", text, flags=re.M)
    assert table is not None
    moved = text.replace(table.group(0), "") + "\n" + table.group(0)
    out = path.with_name(f"{protocol}-last.toml")
    out.write_text(moved, encoding="utf-8")
    return out


def test_every_need_names_a_protocol_and_what_it_leaves() -> None:
    for name, needs in NEEDS.items():
        for need in needs:
            assert need.protocol in PROTOCOLS, (name, need)
            assert need.protocol != name, (name, need)
            assert need.without, (name, need)
    # the lag the issue names, with both fallbacks
    assert "nominal" in next(n.without for n in NEEDS["inertia_friction"]
                             if n.result == "current_loop_time_constant_ms")
    assert "0.0002 s" in next(n.without for n in NEEDS["resonance"]
                              if n.result == "current_loop_time_constant_ms")


@pytest.mark.parametrize("base", ["demo_gimbal_elevation", "demo_gimbal_azimuth"])
def test_the_demo_profiles_keep_every_need_in_order(base: str) -> None:
    check_order(load_profile(base))


def test_inertia_friction_before_current_loop_is_refused(tmp_path: Path) -> None:
    profile = load_profile(str(_moved_last(
        subset_profile(tmp_path, "current_loop", "inertia_friction"), "current_loop")))
    assert list(profile.protocols) == ["inertia_friction", "current_loop"]
    with pytest.raises(ProfileError) as refused:
        check_profile(profile)
    message = str(refused.value)
    assert "\n" not in message
    assert "[protocols.inertia_friction] is listed before [protocols.current_loop]" in message
    assert "current_loop_time_constant_ms" in message


@pytest.mark.slow
def test_the_refusal_comes_before_any_motion(tmp_path: Path) -> None:
    """Failed before: the run certified friction without the lag correction."""
    profile = _moved_last(subset_profile(tmp_path, "current_loop", "inertia_friction"),
                          "current_loop")
    done = run_command(
        ["calibrate", "--profile", str(profile),
         "--unit-serial", "ORDER-1", "--out", str(tmp_path / "out"), "--",
         "--store", "off", "--no-documents"],
        timeout_s=600, cwd=tmp_path,
    )
    assert done.returncode == 4, done.stdout + done.stderr
    errors = [line for line in done.stderr.splitlines() if "listed before" in line]
    assert len(errors) == 1, done.stderr
    assert not (tmp_path / "out" / "ORDER-1").exists()  # nothing recorded, nothing moved


@pytest.mark.slow
def test_a_need_not_configured_runs_on_its_fallback_and_says_so(tmp_path: Path) -> None:
    """inertia_friction without current_loop (and gravity_cable) in the profile: the lag
    taken out is the profile's nominal τ (0 s here: the subset declares none), and its
    certificate entry names each fallback. Failed before: the certificate said nothing."""
    profile = subset_profile(tmp_path, "inertia_friction")
    done = run_command(
        ["calibrate", "--profile", str(profile),
         "--unit-serial", "FALLBACK-1", "--out", str(tmp_path / "out"), "--",
         "--store", "off", "--no-documents"],
        timeout_s=600, cwd=tmp_path,
    )
    path = tmp_path / "out" / "FALLBACK-1" / "certificate.json"
    assert path.is_file(), done.stdout + done.stderr
    cert = json.loads(path.read_text(encoding="utf-8"))
    messages = cert["method"]["protocols"]["inertia_friction"]["messages"]
    assert ("without current_loop's current_loop_time_constant_ms: the profile's nominal "
            "current-loop lag taken out of the sines, its limits a rectangular budget line (0 s "
            "where the profile declares no τ)") in messages
    assert any(m.startswith("without gravity_cable's cable_hysteresis_nm:") for m in messages)
    assert cert["method"]["details"]["inertia_friction"]["current_loop_lag_compensated_s"] == 0
