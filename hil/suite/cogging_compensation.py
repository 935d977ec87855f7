"""cogging_compensation: the protocol's library (spec, excitation, analysis); the test and
its declared measurements are in ``protocols/test_cogging_compensation.py``.

How well the drive's cogging compensation works: the table the cogging protocol wrote
(``cogging_compensation.json``) is loaded into the drive, and the same constant-velocity
pass is run with it cleared and with it loaded (a drive applies it only when its firmware
has ``cogging_compensation``). The residual cogging is the position ripple at the table's
orders; the share of it the table removes is the compensation's effectiveness. Numerics in
:mod:`hil.closed_loop.ripple`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from hil.closed_loop.ripple import position_ripple, ripple_estimate
from hil.details import RunDetails
from hil.drives.base import Capability, DriveInfo
from hil.errors import IdentificationError
from hil.gum import format_result
from hil.identify.estimate import Component, Estimate, with_budget
from hil.motion import CompensationTable, Excitation, Mode, PositionHarmonic
from hil.profile import UnitProfile
from hil.recording import Recording
from hil.suite.cogging import MIN_SAMPLES_PER_PASS
from hil.suite.needs import Need
from hil.suite.protocol import Position, Protocol
from hil.suite.stop_rule import StopRule
from hil.suite.travel import TravelSpec, on_command_grid, runs_from_start, speed_ramp

NAME = "cogging_compensation"
TABLE_LINE = "the table's own uncertainty"  # shared by repeated runs (stop_rule)
REMOVED = "cogging_compensation_removed_pct"
MEASUREMENTS = ("cogging_ripple_uncompensated_urad", "cogging_ripple_compensated_urad",
                REMOVED)
#: a share removed whose U reaches this many points cannot tell a table that removes the
#: cogging (100 %) from one that removes none (0 %): it is stated, not judged
UNRESOLVED_U_PCT = 50.0
#: what it takes from earlier protocols (:mod:`hil.suite.needs`)
TABLE = Need(protocol="cogging", result="compensation_table",
             without="skipped: no compensation table to load")
NEEDS: tuple[Need, ...] = (TABLE,)
#: what the station must have beyond the drive contract
REQUIRES: tuple[Capability, ...] = (Capability.COMPENSATION_TABLE,)


@dataclass(frozen=True, slots=True, kw_only=True)
class Spec(TravelSpec):
    """One constant-velocity pass (after a ramp and ``skip_s``), run twice."""

    speed_rad_s: float
    pass_s: float
    ramp_s: float
    skip_s: float
    min_samples_per_pass: int  # as the cogging protocol: the ripple's floor falls as 1/√N
    stop: StopRule | None = None  # run again until U is reached (hil.suite.stop_rule)

    @classmethod
    def from_profile(cls, profile: UnitProfile, info: DriveInfo) -> Spec:
        """The spec from ``[protocols.cogging_compensation]`` and the drive.

        Raises
        ------
        ProfileError
            A missing, mistyped or unknown key; a pass past the travel limits.
        """
        settings = profile.settings(NAME)
        spec = cls(
            **TravelSpec.envelope(settings, profile, info),
            speed_rad_s=settings.positive("speed_rad_s", 0.3),
            pass_s=settings.positive("pass_s", 1.5),
            ramp_s=settings.positive("ramp_s", 0.1),
            skip_s=settings.positive("skip_s", 0.2),
            min_samples_per_pass=settings.integer("min_samples_per_pass", MIN_SAMPLES_PER_PASS),
            stop=StopRule.from_settings(settings),
        )
        settings.done()
        spec.require_travel(spec.speed_rad_s * (spec.pass_s + spec.ramp_s), protocol=NAME,
                            source=profile.source)
        return spec

    @property
    def needed_sample_rate_hz(self) -> float:
        """Enough samples in the analysed pass (``min_samples_per_pass``)."""
        return self.min_samples_per_pass / (self.pass_s - self.skip_s)

    def command(self) -> np.ndarray:
        """Ramp up, the constant-velocity pass, ramp down (rad/s)."""
        up = speed_ramp(self.speed_rad_s, ramp_s=self.ramp_s, fs_hz=self.fs_hz, up=True)
        down = speed_ramp(self.speed_rad_s, ramp_s=self.ramp_s, fs_hz=self.fs_hz, up=False)
        return np.concatenate([up, np.full(round(self.pass_s * self.fs_hz), self.speed_rad_s),
                               down])

    @property
    def analysed(self) -> slice:
        """The pass's samples after the ramp and ``skip_s``."""
        start = round((self.ramp_s + self.skip_s) * self.fs_hz)
        return slice(start, round((self.ramp_s + self.pass_s) * self.fs_hz))


def table_from_json(data: Mapping[str, Any]) -> CompensationTable:
    """The drive's table from ``cogging_compensation.json`` (format: hil/identify/cogging.py).

    Raises
    ------
    IdentificationError
        The file holds no cogging harmonic.
    """
    cogging = tuple(PositionHarmonic(order=int(h["order"]), amplitude=float(h["amplitude_nm"]),
                                     phase_rad=float(h["phase_rad"])) for h in data["cogging"])
    ripple = tuple(PositionHarmonic(order=int(h["order"]), amplitude=float(h["amplitude"]),
                                    phase_rad=float(h["phase_rad"])) for h in data["kt_ripple"])
    if not cogging and not ripple:
        raise IdentificationError("the compensation table holds no harmonic")
    return CompensationTable(cogging_nm=cogging, kt_ripple=ripple)


def table_relative_uncertainty(data: Mapping[str, Any]) -> dict[int, float]:
    """Per order, the table's ``amplitude_u / amplitude`` (the larger of its cogging and K_t
    ripple entries there): how far, relative to what it cancels at that order, the
    identified table may be off."""
    ratios: dict[int, float] = {}
    rows = [(h, "amplitude_u_nm", "amplitude_nm") for h in data["cogging"]]
    rows += [(h, "amplitude_u", "amplitude") for h in data["kt_ripple"]]
    for h, u_key, a_key in rows:
        if float(h[a_key]) > 0:
            order = int(h["order"])
            ratios[order] = max(ratios.get(order, 0.0), float(h[u_key]) / float(h[a_key]))
    return ratios


def orders(table: CompensationTable) -> list[int]:
    """Every order of the table, cogging and K_t ripple, ascending."""
    return sorted({h.order for h in (*table.cogging_nm, *table.kt_ripple)})


def excitation(spec: Spec) -> tuple[Excitation, Excitation]:
    """The pass with the table cleared and loaded (each from :attr:`Spec.start_rad`,
    reached by ``spec.move_to_start`` from wherever the axis is)."""
    command = spec.command()
    off, on = (Excitation(name=f"pass_{label}", mode=Mode.VELOCITY, fs_hz=spec.fs_hz,
                          command=command) for label in ("uncompensated", "compensated"))
    return off, on


def motion(spec: Spec, runs: tuple[Excitation, Excitation], *,
           position: Callable[[], float]) -> Iterator[Excitation]:
    """The protocol's motion, the one sequence the test runs and the planner sums: each of
    ``runs`` (:func:`excitation`: table cleared, then loaded) after a move to
    :attr:`Spec.start_rad` from ``position()``."""
    return runs_from_start(spec, runs, position=position)


def analyse(off: tuple[Recording, Excitation], on: tuple[Recording, Excitation],
            spec: Spec, table: CompensationTable, *,
            table_relative_u: Mapping[int, float] | None = None,
            ) -> tuple[dict[str, Estimate], list[int]]:
    """The residual ripple without and with the table, and their ratio.

    The residual with the table also carries the table's own uncertainty (identified from
    this calibration's noisy torque): a table off by ``δ`` relative at the order of the
    largest uncompensated ripple leaves about ``δ`` of that ripple, in amplitude and in
    phase, so ``√2·δ·ripple_cleared`` is a Type A line of the compensated ripple
    (``table_relative_u``: δ per order, :func:`table_relative_uncertainty`; a weak
    harmonic's large relative u does not apply to the strong one's ripple).
    """
    found = []
    for recording, exc in (off, on):
        position, _, _ = on_command_grid(recording, exc)
        window = spec.analysed
        t = np.arange(len(position))[window] / spec.fs_hz
        found.append(position_ripple(t, position[window], orders=orders(table)))
    (a_off, u_off, n_off), (a_on, u_on, n_on) = found
    without = ripple_estimate("cogging_ripple_uncompensated_urad", a_off, u_off, order=n_off)
    with_table = ripple_estimate("cogging_ripple_compensated_urad", a_on, u_on, order=n_on)
    by_order = table_relative_u or {}
    delta = by_order.get(n_off, max(by_order.values(), default=0.0))
    if delta > 0:
        with_table = with_table.with_components(Component(
            source=f"{TABLE_LINE} (cogging_compensation.json amplitude_u), times "
                   "the ripple it cancels, amplitude and phase (Type A)", kind="A",
            standard_uncertainty=math.sqrt(2) * delta * without.value, unit="µrad"))
    removed = removed_fraction(without, with_table)
    return ({without.name: without, with_table.name: with_table, removed.name: removed},
            [n_off, n_on])


def removed_fraction(without: Estimate, with_table: Estimate) -> Estimate:
    """``100·(1 − with/without)``: the share of the ripple the table removes (%), both
    budgets propagated to first order. Bounded where the ratio ``without/with`` is not:
    the residual sits near its own noise, the ratio's denominator."""
    value = 100 * (1 - with_table.value / without.value)
    lines = [dataclasses.replace(c, source=f"{c.source} [table cleared]",
                                 sensitivity=c.sensitivity * 100 * with_table.value
                                 / without.value**2) for c in without.components()]
    lines += [dataclasses.replace(c, source=f"{c.source} [table loaded]",
                                  sensitivity=-c.sensitivity * 100 / without.value)
              for c in with_table.components()]
    base = Estimate(name=REMOVED, value=value,
                    standard_uncertainty=0.0, unit="%")
    return with_budget(base, lines, value=value)


def unresolved(estimates: Mapping[str, Estimate]) -> str | None:
    """Why the share removed cannot be judged, or ``None`` when it can.

    The share's U is mostly the residual's U over the ripple before compensation: where
    that ripple is not large against the residual's uncertainty (a motor with little
    cogging, a noisy pass) the percentage says nothing, on any drive, and judging it against
    its limits would hold a good unit for review or fail it. The residual ripple is then
    what is judged, against its absolute limit; the share is stated with the reason.
    """
    removed = estimates[REMOVED]
    if removed.expanded_uncertainty < UNRESOLVED_U_PCT:
        return None
    before = estimates["cogging_ripple_uncompensated_urad"]
    after = estimates["cogging_ripple_compensated_urad"]
    return (f"not resolvable: {format_result(removed.value, removed.expanded_uncertainty, '%')}"
            f" (U ≥ {UNRESOLVED_U_PCT:g} points cannot tell a table that removes the cogging "
            "from one that removes none: the ripple before compensation, "
            f"{format_result(before.value, before.expanded_uncertainty, 'µrad')}, is not large "
            "against the residual's U, "
            f"{format_result(after.value, after.expanded_uncertainty, 'µrad')}); the residual "
            "is judged against its limit instead")


def planned_motion(profile: UnitProfile, info: DriveInfo, at: Position) -> Iterable[Excitation]:
    """The protocol's excitations as the run will command them, from the profile alone."""
    spec = Spec.from_profile(profile, info)
    return motion(spec, excitation(spec), position=at)


@dataclass(frozen=True, slots=True, kw_only=True)
class LargestOrder:
    """The order with the largest position ripple, table cleared and loaded."""

    cleared: int
    loaded: int


@dataclass(frozen=True, slots=True, kw_only=True)
class CoggingCompensationDetails(RunDetails):
    """The certificate's details: the table loaded, its orders and their uncertainty, the
    largest order before and after, and the analysed stretch of each pass (for the plot)."""

    table: str
    orders: tuple[int, ...]
    table_relative_uncertainty: dict[str, float]  # order → u of its amplitude, relative
    largest_order: LargestOrder
    analysed_s: tuple[float, float]


PROTOCOL = Protocol(name=NAME, measurements=tuple(MEASUREMENTS), needs=NEEDS,
                    requires=REQUIRES, planned_motion=planned_motion,
                    details=CoggingCompensationDetails)
