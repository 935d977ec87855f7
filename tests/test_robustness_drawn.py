"""Drawn careless input: Hypothesis mutates the demo profile, a station file, a recording
and a certificate, and each reader answers with its own error (one line naming the file)
or accepts the input; no other exception reaches the user. The corpus of named inputs is
``test_robustness_corpus.py``; this one looks for the inputs nobody named.
"""

from __future__ import annotations

import copy
import json
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hil.certificate.integrity import seal, verify_document
from hil.certificate.model import SCHEMA
from hil.config import builtin_fixture
from hil.drives.base import Capability, DriveInfo
from hil.drives.station import station_from_mapping
from hil.errors import HilError
from hil.motion import Mode
from hil.profile import builtin_profile_path, profile_from_mapping
from hil.recording import parse_recording
from hil.suite.catalogue import check_profile
from hil.suite.plan import check_protocol_settings

DEMO: dict[str, Any] = tomllib.loads(builtin_profile_path().read_text(encoding="utf-8"))
STATION_PATH = builtin_fixture("station_canopen_emulator.toml")
STATION: dict[str, Any] = tomllib.loads(STATION_PATH.read_text(encoding="utf-8"))
DRAWN = settings(max_examples=60, deadline=None, derandomize=True,
                 suppress_health_check=[HealthCheck.too_slow])

#: what a careless hand puts where a value was
VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-10**12, 10**12),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
    st.lists(st.floats(-1e6, 1e6), max_size=4), st.dictionaries(st.text(max_size=5),
                                                                 st.integers(), max_size=2),
)


def _paths(document: dict[str, Any], prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every key path of a nested document (tables and their keys)."""
    found = []
    for key, value in document.items():
        found.append((*prefix, key))
        if isinstance(value, dict):
            found += _paths(value, (*prefix, key))
    return found


@st.composite
def mutated(draw: st.DrawFn, document: dict[str, Any]) -> dict[str, Any]:
    """``document`` with one to three keys deleted, retyped, renamed or added."""
    changed = copy.deepcopy(document)
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(_paths(changed) or [("x",)]))
        parent: Any = changed
        for key in path[:-1]:
            parent = parent.get(key) if isinstance(parent, dict) else None
        if not isinstance(parent, dict):
            continue
        action = draw(st.sampled_from(("delete", "retype", "rename", "add")))
        if action == "delete":
            parent.pop(path[-1], None)
        elif action == "retype":
            parent[path[-1]] = draw(VALUES)
        elif action == "rename" and path[-1] in parent:
            parent[path[-1] + draw(st.sampled_from(("x", "_", "s")))] = parent.pop(path[-1])
        else:
            parent[draw(st.text(min_size=1, max_size=8))] = draw(VALUES)
    return changed


def _refusal(call: Callable[[], object]) -> str | None:
    """The one line a reader refused with, or ``None`` when it accepted the input; any
    other exception than the project's own propagates (and fails the test)."""
    try:
        call()
    except HilError as exc:
        return str(exc)
    return None


def _one_line(message: str | None, source: str) -> bool:
    return message is None or (len(message.splitlines()) == 1 and source in message)


def _planning_info(profile: Any) -> DriveInfo:
    return DriveInfo(vendor="", model="", firmware_version="", serial="",
                     rated_torque_nm=profile.limits.torque_nm, limits=profile.limits,
                     modes=tuple(Mode), max_sample_rate_hz=profile.sample_rate_hz,
                     capabilities=frozenset(Capability), transport="planned")


@DRAWN
@given(document=mutated(DEMO))
def test_a_drawn_profile_is_loaded_or_refused_in_one_line(document: dict[str, Any]) -> None:
    def load() -> None:
        profile = profile_from_mapping(document, source="drawn.toml")
        check_profile(profile)
        check_protocol_settings(profile, _planning_info(profile))

    assert _one_line(_refusal(load), "drawn.toml")


@DRAWN
@given(document=mutated(STATION))
def test_a_drawn_station_file_is_loaded_or_refused_in_one_line(
    document: dict[str, Any],
) -> None:
    message = _refusal(lambda: station_from_mapping(document, source="drawn.toml",
                                                    base_dir=STATION_PATH.parent))
    assert _one_line(message, "drawn.toml")


HEADER = "time_s,velocity_cmd_rad_s,position_rad,velocity_rad_s,torque_nm"
CELLS = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr),
                  st.text(alphabet="0123456789.-e+,x ", max_size=8), st.just(""))


@DRAWN
@given(rows=st.lists(st.lists(CELLS, min_size=0, max_size=7), min_size=0, max_size=150),
       header=st.sampled_from([HEADER, HEADER.replace("time_s", "t"), "", HEADER + ",x"]),
       fill=st.integers(0, 150))
def test_a_drawn_recording_is_read_or_refused_in_one_line(
    rows: list[list[str]], header: str, fill: int,
) -> None:
    good = [f"{i / 1000:.3f},0.1,{i * 1e-4:.6f},0.1,0.02" for i in range(fill)]
    lines = [header, *good, *(",".join(row) for row in rows)]
    message = _refusal(lambda: parse_recording(lines, source="drawn.csv", log_warnings=False))
    assert _one_line(message, "drawn.csv")


def _certificate() -> dict[str, Any]:
    """A small certificate, sealed: one result, one protocol."""
    return seal({
        "schema": SCHEMA, "certificate_id": "U-1-20261127T000000Z-00",
        "results": [{"parameter": "inertia_kg_m2", "value": 0.0036, "unit": "kg·m²",
                     "standard_uncertainty": 2e-5, "coverage_factor": 2.0,
                     "expanded_uncertainty": 4e-5, "nominal": 0.0036,
                     "lower_limit": 0.003, "upper_limit": 0.0042, "outcome": "PASS"}],
        "method": {"protocols": {"inertia_friction": {"outcome": "PASS", "messages": []}}},
        "raw_data": [], "artifacts": [], "outcome": "PASS", "aborted": False,
        "not_measured": [],
    })


@DRAWN
@given(document=mutated(_certificate()))
def test_a_drawn_certificate_is_verified_never_crashed_on(
    tmp_path_factory: Any, document: dict[str, Any],
) -> None:
    folder = Path(tmp_path_factory.mktemp("cert"))
    (folder / "certificate.json").write_text(json.dumps(document, default=str))
    verification = verify_document(document, path=folder / "certificate.json", unit_dir=folder)
    if _sealed_part(document) != _sealed_part(_certificate()):
        assert not verification.verified


def _sealed_part(document: dict[str, Any]) -> tuple[object, object]:
    """What the digest covers, and the digest (the integrity block's other keys are notes)."""
    integrity = document.get("integrity")
    digest = integrity.get("content_sha256") if isinstance(integrity, dict) else integrity
    return ({k: v for k, v in document.items() if k != "integrity"}, digest)
