"""Calibrating the drawn units through the command line, as a test engineer would
(``gimbal-hil calibrate --drive sim``, each in a process of its own:
:mod:`hil.characterise.processes`), each result beside its truth.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hil.characterise.draw import Unit
from hil.characterise.processes import run_command
from hil.characterise.truth import truths
from hil.suite.catalogue import CATALOGUE

#: The protocols an earlier result's budget line may name (``… (gravity_cable)``).
PROTOCOLS = tuple(CATALOGUE)
#: The closed-loop protocols measure behaviour with no truth in the plant's parameters;
#: their run-to-run check is ``bench_compare.py`` (same firmware, other seeds). Left out
#: here, they would only add machine time.
MECHANICS_ONLY = ("not (test_velocity_loop_frf or test_velocity_step or test_tracking or "
                  "test_standstill or test_cogging_compensation)")


def calibrate(unit: Unit, out_dir: Path, *, seed: int | None = None,
              method_bias: str | None = None, reuse: bool = False) -> dict[str, dict[str, Any]]:
    """Calibrate one unit through ``gimbal-hil calibrate``; its results by parameter
    (``method_bias``: a map file or ``off``; default the shipped one; ``reuse``: read a
    certificate already in ``out_dir`` instead)."""
    seed = unit.seed if seed is None else seed
    serial = f"{unit.serial}-s{seed}"
    path = out_dir / serial / "certificate.json"
    if reuse and path.is_file():
        return {r["parameter"]: r for r in json.loads(path.read_text("utf-8"))["results"]}
    extra = ["--", "--no-documents", "--store", "off", "-k", MECHANICS_ONLY] + (
        [] if method_bias is None else ["--method-bias", method_bias])
    run_command(["calibrate", "--drive", "sim", "--profile", str(unit.profile_path),
                 "--unit-serial", serial, "--seed", str(seed), "--out", str(out_dir), *extra])
    if not path.is_file():
        return {}
    certificate = json.loads(path.read_text(encoding="utf-8"))
    return {r["parameter"]: r for r in certificate["results"]}


@dataclass(frozen=True, slots=True, kw_only=True)
class Row:
    """One result of one calibrated unit against its truth."""

    unit: str
    axis: str
    parameter: str
    value: float
    truth: float
    standard_uncertainty: float
    expanded_uncertainty: float
    variant: str = ""  # the unit's drawn simulator choices (hil.characterise.draw)

    @property
    def normalised_error(self) -> float:
        return (self.value - self.truth) / self.standard_uncertainty

    @property
    def covered(self) -> bool:
        return abs(self.value - self.truth) <= self.expanded_uncertainty


def run_population(units: Sequence[Unit], out_dir: Path, *, workers: int = 2,
                   scheduler: str | None = None, method_bias: str | None = None,
                   reuse: bool = False,
                   progress: Callable[[Unit, int], None] | None = None) -> list[Row]:
    """Calibrate every unit (``workers`` at a time here, or on the Dask cluster whose
    ``scheduler`` address is given: :mod:`hil.characterise.cluster`); one row per result
    with a truth, in the units' order whatever the workers' (``progress(unit, results)``
    as each ends)."""

    def ended(unit: Unit, results: dict[str, dict[str, Any]]) -> None:
        if progress is not None:
            progress(unit, len(results))

    work = functools.partial(calibrate, out_dir=out_dir, method_bias=method_bias, reuse=reuse)
    if scheduler is not None:
        from hil.characterise.cluster import map_on_cluster

        found = map_on_cluster(scheduler, work, units, ended)
    else:
        def one(unit: Unit) -> dict[str, dict[str, Any]]:
            results = work(unit)
            ended(unit, results)
            return results

        with ThreadPoolExecutor(max_workers=workers) as pool:
            found = list(pool.map(one, units))
    return [row for unit, results in zip(units, found, strict=True)
            for row in _rows(unit, results)]


def _rows(unit: Unit, results: dict[str, dict[str, Any]]) -> list[Row]:
    truth = truths(unit)
    return [
        Row(unit=unit.serial, axis=unit.axis, parameter=name, value=float(r["value"]),
            truth=truth[name], standard_uncertainty=float(r["standard_uncertainty"]),
            expanded_uncertainty=float(r["expanded_uncertainty"]), variant=unit.variant)
        for name, r in results.items() if name in truth and r["standard_uncertainty"]
    ]
