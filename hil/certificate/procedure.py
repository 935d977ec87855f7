"""What makes two calibrations comparable: the profile without its firmware settings.

``gimbal-hil compare`` refuses two different profiles, yet a firmware regression test
changes exactly the drive's controller settings. The certificate therefore also states
the SHA-256 of the profile with those settings left out: the ``[firmware]`` table, and
the same keys while they still live in ``[plant]``.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from typing import Any

FIRMWARE_TABLE = "firmware"
# the drive controller's settings (issue 11, section 1) wherever the profile keeps them
FIRMWARE_KEYS = frozenset({
    "version", "velocity_kp_nm_s_rad", "velocity_ki_nm_rad", "velocity_filter_hz",
    "current_loop_time_constant_s", "command_delay_samples", "feedforward",
    "cogging_compensation",
})


def profile_sha256_without_firmware(document: Mapping[str, Any]) -> str:
    """SHA-256 of the parsed profile (canonical JSON) without its firmware settings.

    Parameters
    ----------
    document : mapping
        The parsed unit profile (``UnitProfile.raw``).

    Returns
    -------
    str
        Hex digest; equal for two profiles that differ only in ``[firmware]`` (or in the
        firmware keys of ``[plant]``).
    """
    kept = {key: value for key, value in document.items() if key != FIRMWARE_TABLE}
    plant = kept.get("plant")
    if isinstance(plant, Mapping):
        kept["plant"] = {k: v for k, v in plant.items() if k not in FIRMWARE_KEYS}
    text = json.dumps(kept, sort_keys=True, ensure_ascii=False, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()
