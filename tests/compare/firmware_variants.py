"""Firmware variants of a unit profile: the ONE place that knows where the drive's
controller settings live: the profile's ``[firmware]`` table (``[plant]`` in profiles
written before it existed, which a calibration now refuses with a pointer to the move).
"""

from __future__ import annotations

import copy
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import tomli_w

from hil.profile import builtin_profile_path

# the controller settings a firmware release changes (issue 11, section 1)
FIRMWARE_KEYS = (
    "version",
    "velocity_kp_nm_s_rad",
    "velocity_ki_nm_rad",
    "velocity_filter_hz",
    "current_loop_time_constant_s",
    "command_delay_samples",
    "feedforward",
    "cogging_compensation",
)


def profile_document(profile: str | Path | Mapping[str, Any]) -> dict[str, Any]:
    """A profile as a fresh, mutable document: TOML text, a file path, a built-in name
    (``demo_gimbal_elevation``) or an already-parsed mapping (deep-copied)."""
    if isinstance(profile, Mapping):
        return copy.deepcopy(dict(profile))
    if isinstance(profile, Path) or ("\n" not in profile and "=" not in profile):
        path = Path(profile)
        if not path.is_file():
            path = builtin_profile_path(str(profile))
        return tomllib.loads(path.read_text(encoding="utf-8"))
    return tomllib.loads(profile)


def firmware_table(document: Mapping[str, Any]) -> str:
    """The table that holds the drive's controller settings in this profile."""
    return "firmware" if "firmware" in document else "plant"


def firmware_setting(profile: str | Path | Mapping[str, Any], key: str) -> Any:
    """The current value of one controller setting, wherever it lives."""
    document = profile_document(profile)
    return document[firmware_table(document)][key]


def with_firmware(profile: str | Path | Mapping[str, Any], **changes: Any) -> dict[str, Any]:
    """The profile with some controller settings changed (a new document; the input is
    left alone).

    Parameters
    ----------
    profile : str, Path or mapping
        TOML text, a file, a built-in profile name or a parsed document.
    **changes
        Setting name → new value (names as in :data:`FIRMWARE_KEYS`).

    Returns
    -------
    dict
        The document, each setting written into ``[firmware]`` if present, else ``[plant]``.
    """
    document = profile_document(profile)
    table = document.setdefault(firmware_table(document), {})
    for key, value in changes.items():
        if key not in FIRMWARE_KEYS:
            raise KeyError(f"{key} is not a firmware setting ({', '.join(FIRMWARE_KEYS)})")
        table[key] = value
    return document


def write_profile(document: Mapping[str, Any], path: Path) -> Path:
    """Write a profile document as TOML; returns ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(tomli_w.dumps(dict(document)), encoding="utf-8")
    return path
