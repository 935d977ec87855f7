"""A series whose values are all equal (σ = 0) is said in words, not an error (issue 24):
before, ``results spc`` exited 2 with "Nelson rules need a positive σ, got 0.0" and the
fleet report showed such results as bare error lines."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from hil.fleet.commands import fleet_report_html, has_signal, spc_report, trend_table
from tests.fleet.points import drifting_values, runs_for, series

SENTENCE = "all 5 values equal 27.24 Hz: no spread to chart or judge capability on"


def _flat(n: int = 5) -> list:  # type: ignore[type-arg]
    return [replace(p, unit="Hz") for p in series([27.23840162096171] * n, nominal=27.0,
                                                   tolerance=0.2, u=0.5)]


def test_spc_of_an_all_equal_series_says_so_and_signals_nothing() -> None:
    result = spc_report(_flat(), parameter="velocity_bandwidth_hz")
    assert not has_signal(result)  # exit 0
    assert result.capability is None
    table = result.table()
    assert SENTENCE[0].upper() + SENTENCE[1:] + "." in table
    assert "Nelson" not in table
    assert "EWMA" not in table
    document = result.to_json()
    assert document["no_spread"] == SENTENCE
    assert document["signal"] is False
    json.dumps(document)  # JSON-ready


def test_trend_of_an_all_equal_series_says_so() -> None:
    trend = trend_table(_flat(), parameter="velocity_bandwidth_hz")
    assert trend.table().endswith(SENTENCE[0].upper() + SENTENCE[1:] + ".")
    assert trend.to_json()["no_spread"] == SENTENCE
    varied = trend_table(series(drifting_values(5)), parameter="inertia_kg_m2")
    assert varied.no_spread == ""
    assert "no spread" not in varied.table()


def test_the_report_says_it_in_words_and_charts_only_what_varies(tmp_path: Path) -> None:
    varied = series(drifting_values(5))
    path = fleet_report_html({"inertia_kg_m2": varied, "velocity_bandwidth_hz": _flat()},
                             runs_for(varied), tmp_path / "report.html")
    page = path.read_text(encoding="utf-8")
    assert "positive σ" not in page  # the old bare error line
    assert f"velocity_bandwidth_hz: {SENTENCE}." in page
    assert page.count("<img ") == 2  # histogram and I-MR of the varying result only
    assert "<h2 id='velocity_bandwidth_hz'>" not in page
