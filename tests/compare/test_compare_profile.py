"""The profile side of compare: the ``direction`` key, the profile hash without firmware
settings, and the one function that writes a firmware variant."""

from __future__ import annotations

import hashlib

import pytest

from hil.certificate.procedure import profile_sha256_without_firmware
from hil.errors import ProfileError
from hil.profile import load_profile, profile_from_mapping
from tests.compare.firmware_variants import firmware_setting, profile_document, with_firmware


def test_direction_is_read_and_optional() -> None:
    profile = load_profile("demo_gimbal_elevation")
    assert profile.measurement("current_loop_time_constant_ms").direction == "lower"
    assert profile.measurement("inertia_kg_m2").direction is None


def test_a_wrong_direction_names_table_and_key() -> None:
    document = profile_document("demo_gimbal_elevation")
    document["measurements"]["inertia_kg_m2"]["direction"] = "up"
    with pytest.raises(ProfileError, match=r"\[measurements.inertia_kg_m2\].*direction.*"
                                           r"higher, lower"):
        profile_from_mapping(document, source="p.toml")


def test_the_hash_without_firmware_ignores_only_firmware_settings() -> None:
    base = profile_document("demo_gimbal_elevation")
    slower = with_firmware(base, current_loop_time_constant_s=0.0009)
    other_unit = profile_document("demo_gimbal_elevation")
    other_unit["plant"]["inertia_kg_m2"] = 0.004
    other_tolerance = profile_document("demo_gimbal_elevation")
    other_tolerance["measurements"]["inertia_kg_m2"]["tolerance_pct"] = 20
    digest = profile_sha256_without_firmware(base)
    assert profile_sha256_without_firmware(slower) == digest
    assert profile_sha256_without_firmware({**base, "firmware": {"version": "2"}}) == digest
    assert profile_sha256_without_firmware(other_unit) != digest
    assert profile_sha256_without_firmware(other_tolerance) != digest
    assert len(digest) == len(hashlib.sha256().hexdigest())


def test_with_firmware_writes_where_the_settings_live() -> None:
    today = with_firmware("demo_gimbal_elevation", velocity_filter_hz=100.0)
    assert today["firmware"]["velocity_filter_hz"] == 100.0
    assert "velocity_filter_hz" not in today["plant"]
    assert firmware_setting("demo_gimbal_elevation", "velocity_filter_hz") == 300.0
    old = profile_document("demo_gimbal_elevation")
    old["plant"].update(old.pop("firmware"))  # a profile from before [firmware]
    variant = with_firmware(old, velocity_filter_hz=100.0)
    assert variant["plant"]["velocity_filter_hz"] == 100.0
    assert old["plant"]["velocity_filter_hz"] == 300.0  # the input is left alone
    moved = profile_document("demo_gimbal_elevation")
    with pytest.raises(KeyError, match="not a firmware setting"):
        with_firmware(moved, inertia_kg_m2=1.0)
