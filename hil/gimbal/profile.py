"""A gimbal profile: the gimbal's part number and revision and its axes, each an axis
profile (today's unit profile), in the order they are calibrated.

```toml
[gimbal]
part_number = "GMB-2"
revision = "B"
description = "two-axis demo gimbal"

[axes.azimuth]
profile = "demo_gimbal_azimuth.toml"   # beside this file, or a built-in profile name

[axes.elevation]
profile = "demo_gimbal_elevation.toml"

[together]  # optional: for `calibrate --gimbal --together`, beyond what the suite knows
beside = [{azimuth = "stribeck", elevation = "gravity_cable",
           why = "benchmarks/bench_together.py on this gimbal: no result moved beyond 0.2 U"}]
```

A ``beside`` pair runs at the same time, its runs overlapping freely: the gimbal's own
evidence (its coupling is weak enough) that the suite's physics-based rule
(:mod:`hil.beside`) cannot know. The certificate names the pairs that ran so.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

from hil.config import ConfigTable, builtin_fixture, read_toml
from hil.errors import ProfileError
from hil.profile import UnitProfile, load_profile


@dataclass(frozen=True, slots=True, kw_only=True)
class GimbalAxis:
    """One axis of the gimbal: its name and its axis profile."""

    name: str
    profile_path: Path
    profile: UnitProfile


@dataclass(frozen=True, slots=True, kw_only=True)
class DeclaredBeside:
    """Two protocols on different axes the gimbal profile lets run at the same time."""

    protocols: tuple[tuple[str, str], ...]  # (axis, protocol), in the gimbal's axis order
    why: str


@dataclass(frozen=True, slots=True, kw_only=True)
class GimbalProfile:
    """The gimbal: what identifies its type, and its axes in calibration order."""

    source: str
    sha256: str
    part_number: str
    revision: str
    description: str
    axes: tuple[GimbalAxis, ...]
    beside: tuple[DeclaredBeside, ...] = ()


def is_gimbal_profile(name_or_path: str | Path) -> bool:
    """Whether ``name_or_path`` (a file, or a built-in name) is a gimbal profile."""
    try:
        data, _ = read_toml(_path(name_or_path))
    except ProfileError:
        return False
    return "gimbal" in data


def load_gimbal_profile(name_or_path: str | Path) -> GimbalProfile:
    """Read a gimbal profile and every axis profile it names.

    Raises
    ------
    ProfileError
        Naming the file, the table and the key: a missing or unknown key, no axes, an axis
        profile that cannot be read or that states another axis than its table's name.
    """
    path = _path(name_or_path)
    data, payload = read_toml(path)
    document = ConfigTable.root(data, source=str(path))
    gimbal = document.table_at("gimbal")
    part_number = gimbal.string("part_number")
    revision = gimbal.string("revision", "")
    description = gimbal.string("description", "")
    gimbal.done()
    axes = []
    for name, table in document.tables("axes").items():
        profile_path = _axis_profile_path(table.string("profile"), beside=path)
        table.done()
        profile = load_profile(profile_path)
        if profile.axis != name:
            raise table.error("profile", f"{profile_path.name} calibrates the '{profile.axis}' "
                                         f"axis, not '{name}'")
        axes.append(GimbalAxis(name=name, profile_path=profile_path, profile=profile))
    if not axes:
        raise ProfileError("a gimbal profile needs at least one [axes.NAME] table",
                           source=str(path))
    together = document.table_at("together", required=False)
    beside = tuple(_declared(pair, axes) for pair in together.table_list("beside"))
    together.done()
    document.done()
    return GimbalProfile(source=str(path), sha256=hashlib.sha256(payload).hexdigest(),
                         part_number=part_number, revision=revision, description=description,
                         axes=tuple(axes), beside=beside)


def _declared(pair: ConfigTable, axes: list[GimbalAxis]) -> DeclaredBeside:
    """One ``[together] beside`` entry: a protocol of each of two axes, and why."""
    from hil.suite.catalogue import CATALOGUE

    why = pair.string("why")
    chosen = []
    for axis in axes:
        if axis.name not in pair:
            continue
        protocol = pair.string(axis.name)
        if protocol not in axis.profile.protocols:
            raise pair.error(axis.name, f"the {axis.name} profile has no protocol "
                                        f"'{protocol}' (it has: "
                                        f"{', '.join(axis.profile.protocols)})")
        if protocol in CATALOGUE and CATALOGUE[protocol].beside.moves_other:
            raise pair.error(axis.name, f"'{protocol}' moves the other axis: nothing runs "
                                        "beside it")
        chosen.append((axis.name, protocol))
    pair.done()  # a key naming no axis of the gimbal is refused here
    if len(chosen) != 2:
        raise pair.error("why", "a pair names a protocol of each of two axes "
                                f"({', '.join(a.name for a in axes)}), and why")
    return DeclaredBeside(protocols=(chosen[0], chosen[1]), why=why)


def _path(name_or_path: str | Path) -> Path:
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise ProfileError("gimbal profile file not found", source=str(path))
        return path
    found = builtin_fixture(f"{name_or_path}.toml")
    if not found.is_file():
        raise ProfileError(f"no built-in gimbal profile named '{name_or_path}'",
                           source=str(found.parent))
    return found


def _axis_profile_path(text: str, *, beside: Path) -> Path:
    """An axis profile named in a gimbal profile: a path relative to the gimbal profile's
    folder, else a built-in profile name (with or without ``.toml``)."""
    near = beside.parent / text
    if near.is_file():
        return near
    return _path(text.removesuffix(".toml"))
