"""The share of the cogging a compensation table removes is judged only where it can be
resolved: on a motor with little cogging its U reaches past 50 points (it cannot tell a
table that removes the cogging from one that removes none), and the certificate then judges
the residual ripple against its absolute limit and states the share as not resolvable,
instead of holding (or failing) a good unit on a percentage of almost nothing. Simulated
azimuth, noise on, the cogging protocol's own table."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

from hil.closed_loop.ripple import ripple_estimate
from hil.identify.estimate import Estimate
from hil.suite.cogging_compensation import REMOVED, removed_fraction, unresolved
from tests.helpers import subset_profile

PROTOCOLS = ("gravity_cable", "cogging", "cogging_compensation")
DEMO_RIPPLE = (  # the demo azimuth's cogging and K_t ripple, as its profile writes them
    "{ order = 84, amplitude = 0.0004,", "{ order = 168, amplitude = 0.0001,",
    "kt_ripple = [{ order = 42, amplitude = 0.01,")


def _certificate(folder: Path, *, ripple_scale: float) -> dict[str, Any]:
    """A calibration of the demo azimuth's cogging protocols (simulator, seed 1) with its
    cogging and K_t ripple scaled by ``ripple_scale``."""
    path = subset_profile(folder, *PROTOCOLS, base="demo_gimbal_azimuth")
    text = path.read_text(encoding="utf-8")
    for entry in DEMO_RIPPLE:
        head, amplitude = entry.rsplit("= ", 1)
        assert entry in text, entry
        text = text.replace(entry, f"{head}= {float(amplitude[:-1]) * ripple_scale:.3g},")
    path.write_text(text, encoding="utf-8")
    done = subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--profile", str(path), "--drive", "sim",
         "--seed", "1", "--unit-serial", "COG-1", "--out", str(folder / "out"), "--",
         "--store", "off", "--no-documents"],
        capture_output=True, text=True, timeout=300, check=False)
    certificate = folder / "out" / "COG-1" / "certificate.json"
    assert certificate.is_file(), done.stdout[-3000:] + done.stderr[-3000:]
    document: dict[str, Any] = json.loads(certificate.read_text(encoding="utf-8"))
    return document


def test_a_share_removed_of_too_little_cogging_is_stated_and_the_residual_judged(
        tmp_path: Path) -> None:
    document = _certificate(tmp_path, ripple_scale=0.15)
    results = {r["parameter"]: r for r in document["results"]}
    assert "cogging_compensation_removed_pct" not in results
    (missing,) = document["not_measured"]
    assert missing["parameter"] == "cogging_compensation_removed_pct"
    assert missing["reason"].startswith("not resolvable: ")
    assert not missing["required"]
    # what is meaningful is judged: the residual against its absolute limit
    residual = results["cogging_ripple_compensated_urad"]
    assert residual["outcome"] == "PASS", residual
    assert residual["value"] + residual["expanded_uncertainty"] < 20.0
    assert document["outcome"] == "PASS", [(r["parameter"], r["outcome"])
                                           for r in document["results"]]
    # a good unit: its small cogging was found (the table it loaded is no noise)
    peak = results["cogging_peak_nm"]
    assert abs(peak["value"] - 0.0004 * 0.15) <= peak["expanded_uncertainty"], peak


def _ripples(before_urad: float, after_urad: float, after_u_urad: float
             ) -> dict[str, Estimate]:
    without = ripple_estimate("cogging_ripple_uncompensated_urad", before_urad * 1e-6,
                              1e-6, order=84)
    with_table = ripple_estimate("cogging_ripple_compensated_urad", after_urad * 1e-6,
                                 after_u_urad * 1e-6, order=84)
    return {without.name: without, with_table.name: with_table,
            REMOVED: removed_fraction(without, with_table)}


def test_a_resolved_share_is_judged_and_the_line_is_where_it_cannot_tell_all_from_none(
        ) -> None:
    # the demo's typical pass (29 µrad before, 2 ± 1.3 µrad after): judged
    assert unresolved(_ripples(29.0, 2.0, 1.3)) is None
    # the Modbus run held for review: 88 ± 87 % of a 29 µrad ripple
    why = unresolved(_ripples(29.0, 3.5, 10.0))
    assert why is not None
    assert why.startswith("not resolvable: ")
    assert "the residual is judged against its limit instead" in why
