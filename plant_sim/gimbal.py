"""A two-axis gimbal: an outer (azimuth) axis carrying an inner (elevation) axis, each a
:class:`~plant_sim.model.Plant` with its own drive, stepped together with the coupling
torques between them (Ekstrand 2001; Hilkert 2008).

The inner gimbal's inertia tensor about the axes' crossing, in its own frame (x the line of
sight, y the elevation axis, z the zenith when level), gives with ψ the azimuth and θ the
elevation the kinetic energy ``½·[ψ̇ θ̇]·M(θ)·[ψ̇ θ̇]ᵀ``,
``M(θ) = [[J(θ), c(θ)], [c(θ), J_el]]``:

- ``J(θ) = J_base + ΔJ·cos²θ + P·sin2θ`` about the azimuth (the outer plant's
  ``inertia_elevation_kg_m2`` ΔJ and ``inertia_product_kg_m2`` P; its inertia, or its load's
  on a two-mass axis, J_base);
- ``c(θ) = C_level·cosθ + C_vertical·sinθ``: the products of inertia of the elevation axis
  with the zenith and line-of-sight axes (the outer plant's ``inertia_coupling_level_kg_m2``
  and ``inertia_coupling_vertical_kg_m2``). An inner gimbal whose mass sits off its
  elevation axis along that axis has them by the parallel-axis theorem (m·d·e terms), its
  imbalance across the axis adds to ΔJ and P (m·e²); gravity on it is the inner plant's
  ``gravity_mge_nm``.

The single-axis plant is the case of an elevation that does not move (c·θ̈ = 0, and J at the
outer plant's ``elevation_rad``): a gimbal whose coupling terms are zero gives each axis the
recording its own plant gives (``tests/test_gimbal_plant.py``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hil.errors import ProfileError
from hil.motion import Mode
from plant_sim import kernel
from plant_sim.model import _KERNEL_MODE, MotionGuard, Plant, PlantTrace, substeps_for
from plant_sim.params import PlantParams

FloatArray = NDArray[np.float64]

#: the largest c²/(J·J_el) over the elevation the gimbal accepts: the axes exchange their
#: coupling torques a physics step late, an iteration whose error shrinks by this ratio
#: each step (a positive-definite mass matrix keeps it below 1)
MAX_COUPLING_RATIO = 0.5
ELEVATION_GRID = np.linspace(-math.pi, math.pi, 361)


@dataclass(frozen=True, slots=True, kw_only=True)
class AxisBlock:
    """What one axis does over a block of control periods."""

    mode: Mode
    command: FloatArray
    torque_offset: FloatArray | None = None
    guard: MotionGuard | None = None


def carrier_inertia_kg_m2(params: PlantParams) -> float:
    """The inertia of the part that carries an axis's load torques, before any elevation
    term: the load of a two-mass axis, else the axis (``kernel.carrier_inertia``'s)."""
    return params.load_inertia_kg_m2 if params.load_inertia_kg_m2 > 0 else params.inertia_kg_m2


def coupling_vector(outer: PlantParams) -> FloatArray:
    """The kernel's coupling vector (``kernel.C_*``) of an outer plant."""
    vector = np.zeros(kernel.C_SIZE)
    vector[kernel.C_J_BASE] = carrier_inertia_kg_m2(outer)
    vector[kernel.C_DJ] = outer.inertia_elevation_kg_m2
    vector[kernel.C_P] = outer.inertia_product_kg_m2
    vector[kernel.C_CC] = outer.inertia_coupling_level_kg_m2
    vector[kernel.C_CS] = outer.inertia_coupling_vertical_kg_m2
    return vector


def outer_inertia_kg_m2(coupling: FloatArray, elevation_rad: FloatArray) -> FloatArray:
    """J(θ) of the outer carrier (``coupling`` from :func:`coupling_vector`)."""
    return np.asarray(coupling[kernel.C_J_BASE]
                      + coupling[kernel.C_DJ] * np.cos(elevation_rad) ** 2
                      + coupling[kernel.C_P] * np.sin(2.0 * elevation_rad))


def coupling_ratio(outer: PlantParams, inner: PlantParams) -> float:
    """The largest ``c(θ)² / (J(θ)·J_el)`` over the elevation (below 1: a mass matrix)."""
    coupling = coupling_vector(outer)
    c = (coupling[kernel.C_CC] * np.cos(ELEVATION_GRID)
         + coupling[kernel.C_CS] * np.sin(ELEVATION_GRID))
    j_inner = carrier_inertia_kg_m2(inner)
    return float(np.max(c**2 / (outer_inertia_kg_m2(coupling, ELEVATION_GRID) * j_inner)))


class GimbalPlant:
    """Two simulated axes, the ``outer`` carrying the ``inner``, each with its own drive
    loops, stepped together. Each :class:`Plant` keeps its state, noise streams and tables;
    the gimbal advances both in one kernel call. The outer plant's ``elevation_rad``
    follows the inner axis after each block."""

    def __init__(self, outer: Plant, inner: Plant) -> None:
        if outer.fs_hz != inner.fs_hz:
            raise ProfileError(f"the gimbal's drives run at {outer.fs_hz} Hz and "
                               f"{inner.fs_hz} Hz: one control rate is needed")
        ratio = coupling_ratio(outer.params, inner.params)
        if not ratio < MAX_COUPLING_RATIO:
            raise ProfileError(
                f"inertia_coupling_level_kg_m2 and inertia_coupling_vertical_kg_m2 give "
                f"c²/(J·J_el) up to {ratio:.2f} (at most {MAX_COUPLING_RATIO}: the inner "
                "gimbal's products of inertia against both axes' inertias)")
        self.outer = outer
        self.inner = inner
        self._coupling = coupling_vector(outer.params)
        worst = [outer.params.with_changes(elevation_rad=float(el))
                 for el in ELEVATION_GRID[::15]]
        self._substeps = max(substeps_for(params, outer.fs_hz)
                             for params in (*worst, inner.params))
        outer.set_elevation(inner.position_rad)

    @property
    def fs_hz(self) -> float:
        return self.outer.fs_hz

    def run(self, outer: AxisBlock, inner: AxisBlock) -> tuple[PlantTrace, PlantTrace]:
        """Advance both axes one control period per command sample (the two commands are
        equally long); either axis's monitor stops both, and both traces are then shorter."""
        if outer.command.shape != inner.command.shape:
            raise ValueError(f"the axes' commands differ in length: {outer.command.shape[0]} "
                             f"and {inner.command.shape[0]} samples")
        first = self.outer.block(outer.command, outer.torque_offset, guard=outer.guard)
        second = self.inner.block(inner.command, inner.torque_offset, guard=inner.guard)
        run: Callable[..., int] = kernel.run_gimbal_kernel
        done = run(first.arrays, _KERNEL_MODE[outer.mode], first.loop_noise, first.out,
                   second.arrays, _KERNEL_MODE[inner.mode], second.loop_noise, second.out,
                   self._coupling, 1.0 / self.fs_hz, self._substeps)
        traces = self.outer.advance(first, done), self.inner.advance(second, done)
        self.outer.follow_elevation(self.inner.position_rad)  # its parameters say where
        return traces
