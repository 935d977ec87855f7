"""Render the fleet report on a synthetic line (60 units, two stations, a drift in J from
run 35) and print where it went: ``python -m docs.fleet_report_example OUT_DIR``.

The points are the tests' plain dataclasses (what the results store hands over)."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

from hil.fleet.commands import fleet_report_html, freeze_baseline, spc_report
from tests.fleet.points import START, drifting_values, runs_for, series


def main(out_dir: str) -> None:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    inertia = series(drifting_values(60, drift_from=35), reference_every=10)
    friction = [replace(p, unit="N·m") for p in series(
        drifting_values(60, drift_from=999, seed=5, nominal=0.020, sigma=4.0e-4),
        nominal=0.020, tolerance=0.06, u=3.0e-4, reference_every=10)]
    frozen = freeze_baseline(inertia[:30], parameter="inertia_kg_m2", frozen_at=START)
    path = fleet_report_html(
        {"inertia_kg_m2": inertia, "coulomb_friction_nm": friction}, runs_for(inertia),
        out / "fleet_report.html", baselines={"inertia_kg_m2": frozen.to_dict()},
        title="Fleet report — synthetic line, J drifting from run 35")
    print(spc_report(inertia, parameter="inertia_kg_m2", limits_from="baseline",
                     baseline=frozen).table())
    print(path)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "fleet_example")
