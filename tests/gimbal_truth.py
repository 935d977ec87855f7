"""The truth of a drawn inner gimbal (issue 27): an imbalance mass off the axes' crossing
and the payload's own products of inertia, and what they change in the demo gimbal's two
plants, by the parallel-axis theorem (never from the code under test). Shared by the
cross-coupling tests on the simulator and over the CANopen emulator, with the
protocol's passes as both run them."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from hil.drives.base import Drive
from hil.motion import Mode
from hil.recording import Recording
from hil.suite.cross_coupling import Spec, motion
from plant_sim.params import PlantParams

G = 9.81


@dataclasses.dataclass(frozen=True)
class InnerGimbal:
    """The truth of a drawn inner gimbal: a payload with its own products (in its frame:
    x the line of sight, y the elevation axis, z the zenith when level) and an imbalance
    mass ``mass_kg`` at ``(x, y, z)`` metres from the axes' crossing."""

    mass_kg: float
    at_m: tuple[float, float, float]
    own_xy: float  # the payload's own products of inertia (kg·m², as integrals of m·x·y)
    own_yz: float

    @property
    def level(self) -> float:
        """C_level: the mass matrix's (elevation, azimuth) term with the elevation level,
        the tensor's yz element, ``−∫y·z dm``."""
        _, y, z = self.at_m
        return -(self.own_yz + self.mass_kg * y * z)

    @property
    def vertical(self) -> float:
        """C_vertical: minus the tensor's xy element, ``∫x·y dm``."""
        x, y, _ = self.at_m
        return self.own_xy + self.mass_kg * x * y

    @property
    def gravity(self) -> tuple[float, float]:
        """The elevation's holding torque ``m·g·e·cos(el + φ)`` of the mass."""
        x, _, z = self.at_m
        return self.mass_kg * G * math.hypot(x, z), math.atan2(z, x)


def plant_changes(inner: InnerGimbal, *, azimuth: PlantParams, elevation: PlantParams
                  ) -> tuple[dict[str, Any], dict[str, Any]]:
    """The azimuth's and the elevation's plant parameters with ``inner`` mounted: the
    mass adds to the inertias about both axes (parallel axes: ΔJ, P and J_el) and gives the
    elevation axis its products with the other two and its gravity torque."""
    x, y, z = inner.at_m
    m = inner.mass_kg
    mge, phase = inner.gravity
    return ({"inertia_coupling_level_kg_m2": inner.level,
             "inertia_coupling_vertical_kg_m2": inner.vertical,
             "inertia_elevation_kg_m2": azimuth.inertia_elevation_kg_m2 + m * (z * z - x * x),
             "inertia_product_kg_m2": azimuth.inertia_product_kg_m2 + m * x * z,
             "load_inertia_kg_m2": azimuth.load_inertia_kg_m2 + m * (x * x + y * y)},
            {"inertia_kg_m2": elevation.inertia_kg_m2 + m * (x * x + z * z),
             "gravity_mge_nm": elevation.gravity_mge_nm + mge, "gravity_phase_rad": phase})


def coupling_passes(drive: Drive, spec: Spec) -> dict[str, Recording]:
    """The cross-coupling protocol's motion on ``drive`` (enabled): its four passes."""
    passes = {}
    for e in motion(spec, position=lambda: drive.status().position_rad,
                    set_elevation=drive.set_elevation):
        recording = drive.run(e)
        if e.mode is not Mode.POSITION:
            passes[e.name] = recording
    return passes
