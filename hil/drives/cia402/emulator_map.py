"""The emulator presenting itself under a drive model's object map: its own manufacturer
objects (0x2077 averaged torque, 0x2100 waveform, 0x2200 recorder, 0x2300 compensation)
moved to where the map puts them, or removed where the map says ``"absent"``, and the
addresses the master uses translated back to the emulator's own."""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

from canopen.objectdictionary import (
    UNSIGNED8,
    ObjectDictionary,
    ODArray,
    ODRecord,
    ODVariable,
)

from hil.drives.canopen_map import ObjectMap, ObjectRef

#: the emulator's own addresses
TORQUE_MEAN, WAVEFORM, RECORDER, COMPENSATION = 0x2077, 0x2100, 0x2200, 0x2300
CONTROL_PERIOD = (RECORDER, 6)


@dataclass(frozen=True, slots=True)
class Addresses:
    """The master's address → the emulator's own, for relocated objects."""

    objects: dict[int, int] = field(default_factory=dict)
    variables: dict[tuple[int, int], tuple[int, int]] = field(default_factory=dict)

    def native(self, index: int, subindex: int) -> tuple[int, int]:
        """Where the emulator keeps what the master addresses as ``index:subindex``."""
        found = self.variables.get((index, subindex))
        if found is not None:
            return found
        return self.objects.get(index, index), subindex


def present_under(od: ObjectDictionary, object_map: ObjectMap) -> Addresses:
    """Rearrange ``od`` (the emulator's, from its EDS) as ``object_map`` describes the
    drive, and return the translation of the master's addresses."""
    addresses = Addresses()
    wanted = {WAVEFORM: object_map.waveform_index, RECORDER: object_map.recorder_index,
              COMPENSATION: object_map.compensation_index}
    for own, index in wanted.items():
        if own not in od:
            continue
        moved = copy.deepcopy(od[own])
        del od[own]
        if index is None:
            continue
        _renumber(moved, index)
        od.add_object(moved)
        addresses.objects[index] = own
    mean = object_map.torque_mean
    if TORQUE_MEAN in od:
        del od[TORQUE_MEAN]
    if mean is not None:
        _add_variable(od, mean, "Torque actual value averaged")
        addresses.variables[(mean.index, mean.subindex)] = (TORQUE_MEAN, 0)
    period = object_map.control_period
    recorder_period = (object_map.recorder_index, 6)
    if period is not None and (period.index, period.subindex) != recorder_period:
        _add_variable(od, period, "Control period")
        addresses.variables[(period.index, period.subindex)] = CONTROL_PERIOD
    return addresses


def _renumber(obj: ODArray | ODRecord | ODVariable, index: int) -> None:
    obj.index = index
    for member in getattr(obj, "subindices", {}).values():
        member.index = index


def _add_variable(od: ObjectDictionary, ref: ObjectRef, name: str) -> None:
    var = ODVariable(name, ref.index, ref.subindex)
    var.data_type, var.access_type, var.pdo_mappable = ref.code, "ro", True
    var.default = 0
    if ref.subindex == 0:
        od.add_object(var)
        return
    existing = od.get(ref.index)
    record = existing if isinstance(existing, ODRecord | ODArray) else ODRecord(
        f"{name} (record)", ref.index)
    if 0 not in record.subindices:
        count = ODVariable("Highest sub-index supported", ref.index, 0)
        count.data_type, count.access_type, count.default = UNSIGNED8, "const", ref.subindex
        record.add_member(count)
    record.add_member(var)
    if existing is None:
        od.add_object(record)
