"""Bring-up against the object map: each object the map gives is read from the drive, by
its index, subindex and type, before any motion; a map that does not match the drive (an
object it lacks, another size, a scale that makes its rated torque implausible) is refused
in one line naming the map, the role and what the drive answered."""

from __future__ import annotations

import struct

from hil.drives.canopen_map import ObjectMap, ObjectRef
from hil.drives.cia402.link import CanLink
from hil.errors import DriveError, DriveStateError

#: the unit's torque limit over the drive's rated torque, outside which a map's torque
#: scale (0x6076 counts per N·m) is taken for wrong: a factor of 1000 (µN·m for mN·m)
#: lands outside from any sane unit, while a limit a few hundred times the rated torque is
#: left to the check that the drive can represent it (0x6072)
TORQUE_LIMIT_OVER_RATED = (0.002, 500.0)


def mismatch(link: CanLink, object_map: ObjectMap, what: str) -> DriveStateError:
    """The one-line refusal of a map that does not match the drive."""
    return DriveStateError(f"node {link.node_id}: the object map '{object_map.name}' "
                           f"({object_map.source}) {what}: the map does not match this drive")


def read_object(link: CanLink, ref: ObjectRef, object_map: ObjectMap) -> int:
    """``ref``'s value, uploaded by its address (the EDS not consulted) and decoded as the
    map's type.

    Raises
    ------
    DriveStateError
        The drive aborts the upload, or answers with another number of bytes than the type.
    """
    try:
        data = link.upload(ref.index, ref.subindex)
    except DriveError as exc:
        raise mismatch(link, object_map, f"gives {ref}, but the drive answers: {exc}") from None
    size = struct.calcsize("<" + ref.struct_code)
    if len(data) != size:
        raise mismatch(link, object_map, f"gives {ref} ({size} bytes), but the drive answers "
                                         f"{len(data)} bytes")
    return int(struct.unpack("<" + ref.struct_code, data)[0])


def check_objects(link: CanLink, object_map: ObjectMap) -> None:
    """Read every object ``object_map`` gives (its single values, and the highest
    sub-index of its recorder, waveform and compensation objects).

    Raises
    ------
    DriveStateError
        The first one the drive does not have as the map says.
    """
    for ref in object_map.objects():
        read_object(link, ref, object_map)
    for role, index in (("recorder", object_map.recorder_index),
                        ("waveform", object_map.waveform_index),
                        ("compensation_table", object_map.compensation_index)):
        if index is None:
            continue
        try:
            link.upload(index, 0)
        except DriveError as exc:
            raise mismatch(link, object_map, f"gives {role} 0x{index:04X}, but the drive "
                                             f"answers: {exc}") from None


def check_torque_scale(link: CanLink, object_map: ObjectMap, *, rated_torque_nm: float,
                       torque_limit_nm: float) -> None:
    """Refuse a rated torque that the map's scale makes implausible for the unit.

    Raises
    ------
    DriveStateError
        The unit's torque limit is outside :data:`TORQUE_LIMIT_OVER_RATED` times it.
    """
    low, high = TORQUE_LIMIT_OVER_RATED
    ratio = torque_limit_nm / rated_torque_nm if rated_torque_nm > 0 else float("inf")
    if not low <= ratio <= high:
        raise mismatch(link, object_map, f"scales 0x6076 at {object_map.rated_torque_per_nm:g} "
                       f"per N·m: a rated torque of {rated_torque_nm:.4g} N·m against the unit's "
                       f"torque limit of {torque_limit_nm:g} N·m ({ratio:.3g} times it; "
                       f"plausible {low:g} to {high:g})")
