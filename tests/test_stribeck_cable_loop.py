"""The certified static friction is the friction: the cable loop's half-width, which steady
sliding drags along with it, is taken out when the gravity/cable protocol measured it.

A unit whose cable loop is large (4 mN·m against a static friction of 26 mN·m): the
certificate's T_s must hold the plant's T_s within its ±U, where the staircase's own half
difference (T_s + h, what was certified before) is off by several U. Without the
gravity/cable protocol the value is T_s + h, and the certificate says so.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from hil.characterise.processes import run_command
from tests.helpers import subset_profile

HALF_WIDTH_NM = 0.004
STATIC_NM = 0.026
GAIN = 1.01  # the demo's true K_t over the nominal the drive reports with


def _calibrate(tmp_path: Path, *protocols: str) -> dict[str, dict[str, object]]:
    profile = subset_profile(tmp_path, *protocols)
    text = re.sub(r"^cable_hysteresis_nm = .*$", f"cable_hysteresis_nm = {HALF_WIDTH_NM}",
                  profile.read_text(encoding="utf-8"), count=1, flags=re.M)
    profile.write_text(text, encoding="utf-8")
    out = tmp_path / "out"
    run_command(["calibrate", "--drive", "sim", "--profile", str(profile), "--unit-serial",
                 "LOOP-1", "--seed", "3", "--out", str(out), "--", "--store", "off",
                 "--no-documents"], timeout_s=600)
    certificate = json.loads((out / "LOOP-1" / "certificate.json").read_text(encoding="utf-8"))
    messages = [m for p in certificate["method"]["protocols"].values()
                for m in p.get("messages", [])]
    return {**{r["parameter"]: r for r in certificate["results"]},
            "_messages": {"lines": messages}}


def test_the_cable_loop_is_taken_out_of_the_static_friction(tmp_path: Path) -> None:
    found = _calibrate(tmp_path, "gravity_cable", "stribeck")
    static = found["static_friction_nm"]
    value, expanded = float(static["value"]), float(static["expanded_uncertainty"])
    truth = STATIC_NM / GAIN
    assert abs(value - truth) <= expanded, (value, expanded, truth)
    loop = float(found["cable_hysteresis_nm"]["value"])
    assert abs(value + loop - truth) > 2 * expanded  # the staircase alone: T_s + h
    assert any("gravity_cable" in line["component"] and "taken out" in line["component"]
               for line in static["budget"])


def test_without_the_cable_protocol_the_certificate_says_the_loop_is_in(
        tmp_path: Path) -> None:
    found = _calibrate(tmp_path, "stribeck")
    assert any("cable loop's half-width" in line for line in found["_messages"]["lines"])
    assert float(found["static_friction_nm"]["value"]) > (STATIC_NM + HALF_WIDTH_NM / 2) / GAIN
