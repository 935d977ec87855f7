"""What a station can do beyond the drive contract is declared once (``DriveInfo.capabilities``):
a protocol's ``REQUIRES`` is checked against it, the drive methods that use a capability
refuse where it is not declared, and the motion plan leaves out what will be skipped."""

from __future__ import annotations

from dataclasses import replace

import pytest

from hil.drives.base import Capability, Drive, DriveInfo, DriveStatus
from hil.drives.sim import SimDrive
from hil.errors import DriveStateError
from hil.motion import Excitation
from hil.profile import load_profile
from hil.recording import Recording
from hil.suite import catalogue
from hil.suite.plan import planned_motion_s
from tests.helpers import drive_info

PROFILE = load_profile(None)


class ContractOnly(Drive):
    """A drive with the contract and nothing more (no capability declared)."""

    def __init__(self, info: DriveInfo) -> None:
        self._info = info

    @property
    def info(self) -> DriveInfo:
        return self._info

    def enable(self) -> None: ...

    def disable(self) -> None: ...

    def quick_stop(self) -> None: ...

    def status(self) -> DriveStatus:
        raise NotImplementedError

    def run(self, excitation: Excitation) -> Recording:
        raise NotImplementedError


def test_each_protocols_requirements_are_capabilities_of_the_catalogue() -> None:
    assert set(catalogue.REQUIRES) == set(catalogue.PROTOCOLS)
    assert catalogue.REQUIRES["torque_constant"] == (Capability.TORQUE_SENSOR,
                                                      Capability.LOCKED_ROTOR)
    assert catalogue.REQUIRES["inertia_elevation"] == (Capability.ELEVATION_AXIS,)
    assert catalogue.REQUIRES["cogging_compensation"] == (Capability.COMPENSATION_TABLE,)
    assert catalogue.REQUIRES["inertia_friction"] == ()


def test_lacking_names_every_missing_capability_and_nothing_present() -> None:
    info = replace(drive_info(PROFILE, 4000.0), transport="modbus tcp",
                   capabilities=frozenset({Capability.LOCKED_ROTOR}))
    assert info.lacking(()) is None
    assert info.lacking([Capability.LOCKED_ROTOR]) is None
    reason = info.lacking([Capability.TORQUE_SENSOR, Capability.LOCKED_ROTOR,
                           Capability.ELEVATION_AXIS])
    assert reason == ("the station (modbus tcp) lacks: shaft torque sensor; elevation axis "
                      "the harness can move (Drive.set_elevation)")


@pytest.mark.parametrize(("call", "capability"), [
    (lambda d: d.locked_rotor(), Capability.LOCKED_ROTOR),
    (lambda d: d.set_elevation(0.5), Capability.ELEVATION_AXIS),
    (lambda d: d.load_compensation(None), Capability.COMPENSATION_TABLE),
])
def test_a_drive_without_a_capability_refuses_its_method_naming_it(call, capability) -> None:  # type: ignore[no-untyped-def]
    drive = ContractOnly(replace(drive_info(PROFILE, 4000.0), transport="modbus tcp",
                                 capabilities=frozenset()))
    with pytest.raises(DriveStateError, match=r"\(modbus tcp\) lacks: ") as caught:
        call(drive)
    assert capability.value in str(caught.value)


def test_the_simulator_declares_what_it_has() -> None:
    kwargs = {"limits": PROFILE.limits, "fs_hz": PROFILE.sample_rate_hz, "seed": 0}
    assert PROFILE.plant is not None
    with SimDrive(PROFILE.plant, **kwargs) as full:  # type: ignore[arg-type]
        # all but the elevation following a path: a gimbal's (tests/test_sim_gimbal_drive.py)
        assert full.info.capabilities == frozenset(Capability) - {Capability.ELEVATION_MOTION}
    with SimDrive(PROFILE.plant, has_torque_sensor=False, **kwargs) as bare:  # type: ignore[arg-type]
        assert bare.info.lacking(catalogue.REQUIRES["torque_constant"]) is not None
        with pytest.raises(DriveStateError, match="locked-rotor fixture"), bare.locked_rotor():
            pass


def test_the_plan_holds_no_motion_for_a_protocol_the_station_cannot_run() -> None:
    full = drive_info(PROFILE, PROFILE.sample_rate_hz)
    without = replace(full, capabilities=full.capabilities - {Capability.TORQUE_SENSOR})
    planned, lacking = planned_motion_s(PROFILE, full), planned_motion_s(PROFILE, without)
    assert planned["torque_constant"] > 0
    assert lacking["torque_constant"] == 0
    before = list(PROFILE.protocols)[:list(PROFILE.protocols).index("torque_constant")]
    assert before
    assert all(lacking[name] == planned[name] for name in before)
