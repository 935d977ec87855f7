"""How the fleet report reads (issue 24, "The fleet report"): whole-number axes for run
numbers and counts, a quantity and unit on every axis, capability cells that do not wrap,
and a size fit to e-mail (a three-unit report was 1.9 MB: ~60 kB of full-colour PNG per
result)."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hil.fleet.commands import fleet_report_html, spc_report
from hil.fleet.plots import histogram_figure, imr_figure
from hil.fleet.spc import SpcResult
from tests.fleet.points import drifting_values, runs_for, series


def _three_units(seed: int = 0, unit: str = "kg·m²") -> list:  # type: ignore[type-arg]
    values = 3.6e-3 + 2e-5 * np.random.default_rng(seed).standard_normal(3)
    return [replace(p, unit=unit) for p in series(values)]


def _drawn(figure: Any) -> list[Any]:
    figure.canvas.draw()
    return list(figure.axes)


def _visible_ticks(axis: Any, low: float, high: float) -> np.ndarray:
    ticks = np.asarray(axis.get_ticklocs(), dtype=float)
    return ticks[(ticks >= low) & (ticks <= high)]


@pytest.fixture
def few() -> SpcResult:
    return spc_report(_three_units(), parameter="inertia_kg_m2")


def test_run_numbers_and_counts_have_whole_number_ticks(few: SpcResult) -> None:
    import matplotlib.pyplot as plt

    charts = imr_figure(few)
    try:
        bottom = _drawn(charts)[-1]
        ticks = _visible_ticks(bottom.xaxis, *sorted(bottom.get_xlim()))
        assert ticks.size >= 2
        np.testing.assert_array_equal(ticks, np.round(ticks))  # runs 1, 2, 3: not 1.5
    finally:
        plt.close(charts)
    histogram = histogram_figure(few)
    try:
        (ax,) = _drawn(histogram)
        counts = _visible_ticks(ax.yaxis, *sorted(ax.get_ylim()))
        np.testing.assert_array_equal(counts, np.round(counts))
    finally:
        plt.close(histogram)


def test_every_axis_names_its_quantity_and_unit(few: SpcResult) -> None:
    import matplotlib.pyplot as plt

    charts, histogram = imr_figure(few), histogram_figure(few)
    try:
        charts_axes, (hist_ax,) = _drawn(charts), _drawn(histogram)
        for ax in charts_axes:
            assert ax.get_ylabel().endswith("[kg·m²]"), ax.get_ylabel()
        assert charts_axes[-1].get_xlabel() == "run number (time order)"
        assert hist_ax.get_xlabel() == "inertia_kg_m2 [kg·m²]"
        assert hist_ax.get_ylabel() == "runs [count]"
    finally:
        plt.close(charts)
        plt.close(histogram)
    unitless = spc_report(_three_units(unit=""), parameter="tracking_ff_reduction")
    charts = imr_figure(unitless)
    try:
        assert all(ax.get_ylabel().endswith("(no unit)") for ax in _drawn(charts))
    finally:
        plt.close(charts)


def test_capability_cells_do_not_wrap_and_the_table_shows_what_its_heads_say(
    tmp_path: Path,
) -> None:
    points = series(drifting_values(30))
    page = fleet_report_html({"inertia_kg_m2": points}, runs_for(points),
                             tmp_path / "r.html").read_text(encoding="utf-8")
    assert re.search(r"th, td \{[^}]*white-space: nowrap", page)
    row = re.search(r"<tr><td class='l'><a href='#inertia_kg_m2'>.*?</tr>", page)
    assert row is not None
    cells = re.findall(r"<td>([^<]*)</td>", row.group(0))
    # n, Cpk [CI], Ppk [CI], Cp, Pp: intervals only where the heads announce them
    assert re.fullmatch(r"\d+\.\d\d \[-?\d+\.\d\d, \d+\.\d\d\]", cells[1])
    assert re.fullmatch(r"\d+\.\d\d", cells[3])
    assert re.fullmatch(r"\d+\.\d\d", cells[4])


def test_a_three_unit_report_is_small_enough_to_mail(tmp_path: Path) -> None:
    results = {f"result_{k:02d}": _three_units(seed=k) for k in range(6)}
    path = fleet_report_html(results, runs_for(results["result_00"]), tmp_path / "r.html")
    per_result_bytes = path.stat().st_size / len(results)
    # 39 results (the demo elevation unit's) stay well under 1 MB: below 20 kB each
    assert per_result_bytes < 20_000, per_result_bytes
