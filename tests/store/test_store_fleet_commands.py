"""``gimbal-hil results spc / export / yield / report`` over a real store: the fleet
statistics of :mod:`hil.fleet` on stored runs; ``spc`` gates the newest unit against a
frozen baseline (exit 1 on a signal)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from store_variants import SERIAL, with_value

from hil.cli import main

NAME = "inertia_kg_m2"


def _results(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    capsys.readouterr()
    code = main(["results", *args])
    return code, capsys.readouterr().out


def _with_value(text: str, value: float, index: int, tmp: Path) -> Path:
    return with_value(text, name=NAME, value=value, serial=f"FLT-{index:04d}", index=index,
                      folder=tmp)


def test_spc_gates_the_newest_unit_on_a_frozen_baseline(
    store_url: str, calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = ["--store", store_url]
    text = (calibrated / SERIAL / "certificate.json").read_text(encoding="utf-8")
    values = 0.0036 + np.random.default_rng(4).normal(0, 2e-6, 30)
    for i, value in enumerate(values):
        assert _results(capsys, "ingest", str(_with_value(text, value, i, tmp_path)),
                        *store)[0] == 0
    code, out = _results(capsys, "spc", "baseline", "freeze", NAME, *store)
    assert code == 0
    assert "frozen from 30 runs" in out
    code, out = _results(capsys, "spc", NAME, *store, "--json")
    report = json.loads(out)
    assert code == 0
    assert report["signal"] is False
    # the next unit 6 σ off: rule 1 on the newest run, exit 1
    outlier = _with_value(text, 0.0036 + 12e-6, 31, tmp_path)
    assert _results(capsys, "ingest", str(outlier), *store)[0] == 0
    code, out = _results(capsys, "spc", NAME, *store)
    assert code == 1
    assert "SIGNAL" in out
    assert main(["results", "spc", "a", "b", *store]) == 2  # one name, or baseline freeze

    exported = tmp_path / "inertia.csv"
    assert _results(capsys, "export", NAME, "--output", str(exported), *store)[0] == 0
    with exported.open(encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 31
    assert sorted(float(r["value"]) for r in rows) == sorted([*values, 0.0036 + 12e-6])
    code, out = _results(capsys, "yield", *store, "--json")
    assert code == 0
    assert json.loads(out)["rows"]
    page = tmp_path / "fleet.html"
    assert _results(capsys, "report", "--html", str(page), "--parameters", NAME, *store)[0] == 0
    assert NAME in page.read_text(encoding="utf-8")
