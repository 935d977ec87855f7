"""Run-to-run scatter a result's budget does not state, measured over identical reruns.

``benchmarks/bench_compare.py --write-map`` calibrates the same simulated unit with the
same firmware under many noise seeds. Where the differences scatter more than their
budgets say (the root mean square of ``Δ/u(Δ)`` above the χ² 95 % bound), the excess per
run, ``s² = (mean Δ² − mean u(Δ)²)/2``, is written to ``fixtures/compare_repeatability.toml``
and a comparison adds it to each side as an independent line of the difference's budget.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from hil.config import ConfigTable, builtin_fixture, read_results_by_axis

REPEATABILITY_FILE = "compare_repeatability.toml"


@dataclass(frozen=True, slots=True, kw_only=True)
class Repeatability:
    """Extra run-to-run standard deviation of one result (relative: a fraction of it)."""

    name: str
    relative: bool
    scatter: float
    pairs: int

    def standard_uncertainty(self, value: float) -> float:
        """The extra scatter of one run, in the result's unit."""
        return self.scatter * abs(value) if self.relative else self.scatter

    @property
    def source(self) -> str:
        return (f"run-to-run scatter beyond the budget ({self.pairs} identical-firmware "
                "reruns, bench_compare)")


@dataclass(frozen=True, slots=True, kw_only=True)
class RepeatabilityMap:
    source: str
    sha256: str
    by_axis: Mapping[str, Mapping[str, Repeatability]]

    def entry(self, axis: str, name: str) -> Repeatability | None:
        return self.by_axis.get(axis, {}).get(name)


NO_MAP = RepeatabilityMap(source="off", sha256="", by_axis={})


def load_repeatability(path: Path | None = None) -> RepeatabilityMap:
    """Read a repeatability map (default: the one shipped in ``fixtures/``).

    Parameters
    ----------
    path : Path or None
        The map's file.

    Returns
    -------
    RepeatabilityMap
        Entries by the certificate's ``unit.axis`` and result name.

    Raises
    ------
    ProfileError
        A missing, mistyped or unknown key, naming file, table and key.
    """
    path = path or builtin_fixture(REPEATABILITY_FILE)
    sha256, by_axis = read_results_by_axis(path, _entry)
    return RepeatabilityMap(source=str(path), sha256=sha256, by_axis=by_axis)


def _entry(name: str, table: ConfigTable) -> Repeatability:
    entry = Repeatability(
        name=name,
        relative=table.choice("scale", ("relative", "absolute")) == "relative",
        scatter=table.non_negative("scatter"),
        pairs=table.integer("pairs"),
    )
    table.done()
    return entry
