"""Every command function on plain-dataclass points (what the results store hands over):
baseline freeze and round trip, spc, trend, export, first-pass yield and the HTML report."""

from __future__ import annotations

import base64
import csv
import json
import re
import sys
from dataclasses import replace
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest

from hil.errors import InputError
from hil.fleet.baseline import MIN_BASELINE_POINTS, Baseline
from hil.fleet.commands import (
    export_rows,
    first_pass_yield,
    fleet_report_html,
    freeze_baseline,
    has_signal,
    spc_report,
    trend_table,
    yield_table,
)
from hil.fleet.series import SERIES_FIELDS
from hil.gum import rounded_pair
from tests.fleet.points import START, Run, drifting_values, runs_for, series

FLOWRATE = [49.6, 47.6, 49.9, 51.3, 47.8, 51.2, 52.6, 52.4, 53.6, 52.1]  # NIST 6.3.2.2


def test_baseline_needs_25_runs_and_round_trips_through_json() -> None:
    points = series(drifting_values(40))
    with pytest.raises(InputError, match="at least 25 runs, got 24"):
        freeze_baseline(points[:24], parameter="inertia_kg_m2", frozen_at=START)
    frozen = freeze_baseline(points[:30], parameter="inertia_kg_m2", frozen_at=START)
    assert frozen.n == 30 == MIN_BASELINE_POINTS + 5
    x = np.array([p.value for p in points[:30]])
    assert frozen.centre == pytest.approx(float(x.mean()))
    assert frozen.mr_bar == pytest.approx(float(np.abs(np.diff(x)).mean()))
    again = Baseline.from_dict(json.loads(json.dumps(frozen.to_dict())))
    assert again == frozen


@pytest.mark.parametrize(("change", "message"), [
    ({"n": 24}, "'n' is 24"),
    ({"centre": "x"}, "'centre' must be a number"),
    ({"mr_bar": 0.0}, "'mr_bar' must be positive"),
    ({"run_ids": [1, 2]}, "'run_ids'"),
    ({"n": True}, "'n' must be an integer"),
])
def test_a_bad_baseline_dict_is_named(change: dict[str, object], message: str) -> None:
    good = freeze_baseline(series(drifting_values(30)), parameter="p",
                           frozen_at=START).to_dict()
    with pytest.raises(InputError, match=message) as caught:
        Baseline.from_dict({**good, **change}, source="baselines/p.json")
    assert str(caught.value).startswith("baselines/p.json: ")
    missing = dict(good)
    del missing["unit"]
    with pytest.raises(InputError, match="missing key 'unit'"):
        Baseline.from_dict(missing)


def test_spc_on_the_nist_flowrate_example_has_no_signal() -> None:
    points = series(FLOWRATE, nominal=50.0, tolerance=0.2, u=0.5, unit="gal/min")
    result = spc_report(points, parameter="flow_rate")
    assert round(result.limits.ucl, 4) == 55.8041
    assert not has_signal(result)
    assert result.capability is not None
    assert result.capability.n == 10
    assert "No signal." in result.table()


def test_spc_against_a_frozen_baseline_flags_the_drift() -> None:
    values = drifting_values(60, drift_from=35)
    points = series(values)
    frozen = freeze_baseline(points[:30], parameter="inertia_kg_m2", frozen_at=START)
    result = spc_report(points, parameter="inertia_kg_m2", limits_from="baseline",
                        baseline=frozen.to_dict(), rules="all")
    assert result.limits.source == "baseline"
    assert result.limits.centre == frozen.centre
    assert has_signal(result)
    assert set(result.rule_hits) == set(range(1, 9))
    # the shift rules and the EWMA fire, and only once the drift has begun (index 34 is the
    # first drifted run); rule 6 also fires twice inside the baseline (runs 21 and 23 of
    # this seed), the false-alarm price of the extra sensitivity
    for rule in (1, 2, 5):
        assert result.rule_hits[rule]
        assert min(result.rule_hits[rule]) >= 34
    assert result.ewma is not None
    assert result.ewma.signals
    assert min(result.ewma.signals) >= 34
    document = json.loads(json.dumps(result.to_json()))
    assert document["signal"] is True
    rule2 = document["rules"]["2"]
    assert rule2["run_ids"] == [points[i].run_id for i in rule2["indices"]]
    text = result.table()
    u = result.typical_u
    assert rounded_pair(result.limits.ucl, u)[0] in text
    assert "SIGNAL" in text
    assert "frozen baseline of 30 runs" in text


def test_the_gate_can_look_at_the_newest_runs_only() -> None:
    """Centre 10, σ 1 frozen; ±0.3 about it with one 14.0 at index 5: rule 1 fires at 5 (4σ),
    the moving ranges into and out of it (4.3 and 3.7) pass UCL 3.267·1.128 = 3.685, the
    EWMA (λ = 0.2) rises to 0.8 < its 0.97 limit, nothing else fires."""
    values = [10.0 + 0.3 * (-1) ** i for i in range(40)]
    values[5] = 14.0
    points = series(values, nominal=10.0, tolerance=0.5, u=0.1, unit="N·m")
    frozen = Baseline(parameter="p", unit="N·m", n=25, centre=10.0, mr_bar=1.128,
                      first_started_at="", last_started_at="", frozen_at="", run_ids=())
    result = spc_report(points, parameter="p", limits_from="baseline", baseline=frozen)
    assert result.rule_hits == {1: [5], 2: [], 5: [], 6: []}
    assert result.mr_hits == [5, 6]
    assert result.ewma is not None
    assert result.ewma.signals == []
    assert has_signal(result)
    assert has_signal(result, last=35)  # runs 5 … 39
    assert not has_signal(result, last=34)  # runs 6 … 39
    assert has_signal(result, last=34, include_mr=True)


def test_spc_leaves_reference_units_out_and_checks_its_input() -> None:
    points = series(drifting_values(40), reference_every=5)
    result = spc_report(points, parameter="p")
    assert result.n == 32
    assert result.excluded_reference == 8
    assert all(not p.is_reference for p in result.points)
    assert spc_report(points, parameter="p", include_reference=True).n == 40
    with pytest.raises(InputError, match="none is frozen"):
        spc_report(points, parameter="p", limits_from="baseline")
    with pytest.raises(InputError, match="'data' or 'baseline'"):
        spc_report(points, parameter="p", limits_from="database")
    with pytest.raises(InputError, match="at least 2 runs"):
        spc_report(points[:1], parameter="p")
    frozen = freeze_baseline(points, parameter="p", frozen_at=START)
    named = spc_report(points, limits_from="baseline", baseline=frozen.to_dict())
    assert named.parameter == "p"  # the baseline's name when none is given
    with pytest.raises(InputError, match="not 'q'"):
        spc_report(points, parameter="q", limits_from="baseline", baseline=frozen)
    mixed = [*points[:5], replace(points[5], unit="g·m²")]
    with pytest.raises(InputError, match="mixes units"):
        spc_report(mixed, parameter="p")


def test_spc_without_limits_says_why_there_is_no_capability() -> None:
    points = [replace(p, lower_limit=None, upper_limit=None)
              for p in series(drifting_values(30))]
    result = spc_report(points, parameter="p")
    assert result.capability is None
    assert "no specification limits" in result.table()


def test_trend_filters_and_rounds_as_gum_asks() -> None:
    points = series([0.0036123456, 0.0036051, 0.0036222, 0.0035999])
    everything = trend_table(list(reversed(points)), parameter="inertia_kg_m2")
    assert [p.run_id for p in everything.points] == [p.run_id for p in points]
    assert "0.003612" in everything.table()
    assert "0.000020" in everything.table()
    st2 = trend_table(points, station="ST2", since=START + timedelta(hours=3))
    assert [p.run_id for p in st2.points] == ["run-0003"]
    with pytest.raises(InputError, match="time zone"):
        trend_table(points, since=START.replace(tzinfo=None))
    naive = [replace(points[0], started_at=START.replace(tzinfo=None)), *points[1:]]
    with pytest.raises(InputError, match="time zone"):
        trend_table(naive)
    document = json.loads(json.dumps(everything.to_json()))
    assert document["points"][0]["value"] == 0.0036123456


def test_export_csv_round_trips_every_field(tmp_path: Path) -> None:
    points = series(drifting_values(12), reference_every=4)
    points[0] = replace(points[0], lower_limit=None)
    out = export_rows(points, format="csv", path=tmp_path / "rows.csv")
    with out.open(encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    assert list(rows[0]) == list(SERIES_FIELDS)
    assert len(rows) == 12
    assert rows[0]["lower_limit"] == ""
    assert [float(r["value"]) for r in rows] == [p.value for p in points]
    assert [r["is_reference"] for r in rows].count("true") == 3
    assert rows[1]["started_at"] == points[1].started_at.isoformat()


def test_export_parquet(tmp_path: Path) -> None:
    pq = pytest.importorskip("pyarrow.parquet", reason="pyarrow is the parquet extra")
    points = series(drifting_values(12))
    table = pq.read_table(export_rows(points, format="parquet", path=tmp_path / "r.parquet"))
    assert table.column_names == list(SERIES_FIELDS)
    assert table.column("value").to_pylist() == [p.value for p in points]
    assert table.column("started_at").to_pylist() == [p.started_at for p in points]


def test_export_errors(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    points = series(drifting_values(3))
    with pytest.raises(InputError, match="format 'xlsx'"):
        export_rows(points, format="xlsx", path=tmp_path / "r.xlsx")
    with pytest.raises(InputError, match="does not exist"):
        export_rows(points, format="csv", path=tmp_path / "missing" / "r.csv")
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # as on a machine without it
    with pytest.raises(InputError, match="needs pyarrow"):
        export_rows(points, format="parquet", path=tmp_path / "r.parquet")


def test_first_pass_yield_per_station_and_day() -> None:
    points = series(drifting_values(28, drift_from=100), step=timedelta(hours=6))
    runs = runs_for(points)
    # an aborted attempt before unit 0's first pass, and a golden unit, change nothing
    runs.append(Run(serial=points[0].serial, station="ST1", started_at=START - timedelta(1),
                    outcome="FAIL", attempt=0, aborted=True, is_reference=False))
    runs.append(Run(serial="GOLDEN", station="ST1", started_at=START, outcome="FAIL",
                    attempt=1, aborted=False, is_reference=True))
    by_station = {row.station: row for row in first_pass_yield(runs, by="station")}
    for station in ("ST1", "ST2"):
        units = [i for i, p in enumerate(points) if p.station == station]
        first_failed = [i for i in units if i % 7 == 3]
        row = by_station[station]
        assert row.units == len(units)
        assert row.failed == len(first_failed)
        assert row.first_pass_yield == pytest.approx(
            (len(units) - len(first_failed)) / len(units))
    by_day = first_pass_yield(runs, by="day")
    # runs 6 h apart from 08:00: three on the first day, then four a day, one left over
    assert [row.units for row in by_day] == [3, 4, 4, 4, 4, 4, 4, 1]
    assert sum(row.failed for row in by_day) == 4
    with pytest.raises(InputError, match="grouping"):
        first_pass_yield(runs, by="week")
    result = yield_table(runs, by="station_day")
    assert sum(row["units"] for row in result.to_json()["rows"]) == 28  # type: ignore[index]
    assert "first-pass yield per station and day" in result.table()
    assert "ST2         2026-03-02" in result.table()


def test_fleet_report_is_one_self_contained_page(tmp_path: Path) -> None:
    steady = series(drifting_values(40, drift_from=100, seed=3))
    drifting = series(drifting_values(60, drift_from=35), unit="N·m")
    frozen = freeze_baseline(drifting[:30], parameter="coulomb_friction_nm", frozen_at=START)
    out = fleet_report_html(
        {"inertia_kg_m2": steady, "coulomb_friction_nm": drifting, "lonely": steady[:1]},
        runs_for(steady), tmp_path / "report.html",
        baselines={"coulomb_friction_nm": frozen.to_dict()})
    page = out.read_text(encoding="utf-8")
    images = re.findall(r"src='data:image/png;base64,([^']+)'", page)
    assert len(images) == 4  # histogram + charts for each of the two charted parameters
    assert all(base64.b64decode(data)[:8] == b"\x89PNG\r\n\x1a\n" for data in images)
    assert "http://" not in page
    assert "https://" not in page
    cpk = {name: spc_report(points, parameter=name).capability
           for name, points in (("inertia_kg_m2", steady), ("coulomb_friction_nm", drifting))}
    weakest_first = sorted(cpk, key=lambda name: cpk[name].cpk.value)  # type: ignore[union-attr]
    table = page[page.index("Capability, weakest first"):page.index("First-pass yield")]
    positions = [table.index(f"#{name}'") for name in weakest_first]
    assert positions == sorted(positions)
    assert "lonely: spc for &#x27;lonely&#x27; needs at least 2 runs" in page
    assert "first-pass yield" in page
    assert "ST1" in page
