"""Ingest real certificates into SQLite and PostgreSQL: every field, idempotence, old
certificate folders, the queries statistics read, baselines."""

from __future__ import annotations

import json
import shutil
from datetime import timedelta
from pathlib import Path

import pytest
from sqlalchemy import func, select
from store_variants import SERIAL, variant

from hil.errors import InputError
from hil.store import (
    ingest_certificate,
    ingest_tree,
    load_baseline,
    open_store,
    result_series,
    save_baseline,
)
from hil.store.ingest import ingest_text
from hil.store.query import history, run_results, run_summaries, units
from hil.store.schema import protocol_outcomes, recordings, results, runs


def _counts(store_url: str) -> dict[str, int]:
    store = open_store(store_url)
    with store.engine.connect() as connection:
        found = {t.name: connection.execute(select(func.count()).select_from(t)).scalar_one()
                 for t in (runs, protocol_outcomes, results, recordings)}
    store.close()
    return found


def test_a_certificate_becomes_one_run_with_every_field(store_url: str,
                                                        calibrated: Path) -> None:
    path = calibrated / SERIAL / "certificate.json"
    cert = json.loads(path.read_text(encoding="utf-8"))
    store = open_store(store_url)
    done = ingest_certificate(store, path)
    assert done.new
    assert done.certificate_id == cert["certificate_id"]
    assert done.run_id == cert["run"]["id"]
    (summary,) = history(store, SERIAL)
    assert summary.certificate_id == cert["certificate_id"]
    assert summary.operator == "tester"
    assert summary.station == cert["run"]["station"]
    assert summary.attempt == cert["run"]["attempt"] == 2  # the second calibration
    assert summary.outcome == cert["outcome"] == "PASS"
    assert summary.started_at.isoformat() == cert["dates"]["calibration_started"]
    stored = run_results(store, done.run_id)
    assert set(stored) == {r["parameter"] for r in cert["results"]}
    for r in cert["results"]:
        row = stored[r["parameter"]]
        for key in ("value", "standard_uncertainty", "coverage_factor",
                    "expanded_uncertainty", "nominal", "lower_limit", "upper_limit",
                    "marginal_fraction", "outcome", "unit", "protocol"):
            assert row[key] == r[key], (r["parameter"], key)
    with store.engine.connect() as connection:
        run = connection.execute(select(runs)).one()
        files = {row.path: row.sha256 for row in connection.execute(select(recordings))}
        protocols = {row.protocol: row.outcome
                     for row in connection.execute(select(protocol_outcomes))}
    assert run.profile_sha256 == cert["method"]["profile_sha256"]
    assert run.software_version == cert["software"]["version"]
    assert run.firmware_version == cert["drive"]["firmware_version"]
    assert run.drive_model == cert["drive"]["model"]
    assert run.aborted is False
    assert run.is_reference is False
    assert files == {f["file"]: f["sha256"] for f in cert["raw_data"]}
    assert protocols == {n: p["outcome"] for n, p in cert["method"]["protocols"].items()}
    store.close()


def test_calibrate_stores_in_out_by_default_and_nowhere_with_store_off(
    calibrated: Path,
) -> None:
    (first,) = (json.loads(p.read_text(encoding="utf-8"))
                for p in (calibrated / SERIAL / "history").glob("*/certificate.json"))
    store = open_store(f"sqlite:///{calibrated / 'results.sqlite'}")
    (stored,) = history(store, SERIAL)
    store.close()
    assert stored.certificate_id == first["certificate_id"]
    assert stored.run_id == first["run"]["id"]
    assert stored.attempt == 1


def test_the_same_certificate_twice_is_one_run(store_url: str, calibrated: Path) -> None:
    path = calibrated / SERIAL / "certificate.json"
    store = open_store(store_url)
    assert ingest_certificate(store, path).new
    before = _counts(store_url)
    assert not ingest_certificate(store, path).new
    assert _counts(store_url) == before
    assert before["runs"] == 1
    assert [d.new for d in ingest_tree(store, calibrated)] == [True, False]  # + history
    after_tree = _counts(store_url)
    assert [d.new for d in ingest_tree(store, calibrated)] == [False, False]
    assert _counts(store_url) == after_tree
    assert after_tree["runs"] == 2
    store.close()


def test_two_runs_started_in_the_same_second_keep_their_order(store_url: str,
                                                               calibrated: Path) -> None:
    """The certificate's start time has whole seconds: two simulated runs of one unit
    started in the same second tied, and the random run ids put the second run first
    (the outbox test, once in a CI dry run)."""
    text = (calibrated / SERIAL / "certificate.json").read_text(encoding="utf-8")
    first = variant(text, serial="TIE-1", index=0, attempt=1,
                    id="ffffffff-ffff-4fff-bfff-ffffffffffff")
    second = variant(text, serial="TIE-1", index=0, attempt=2,
                     id="00000000-0000-4000-8000-000000000000")
    store = open_store(store_url)
    for name, certificate in (("first", first), ("second", second)):
        ingest_text(store, certificate, source=name)
    order = [run.attempt for run in history(store, "TIE-1")]
    store.close()
    assert order == [1, 2]


def test_old_certificate_folders_are_ingested_with_their_history(
    store_url: str, calibrated: Path, tmp_path: Path
) -> None:
    """Certificates written before the store existed have no ``run`` block: the run id
    comes from the certificate id, attempts are counted in time order."""
    old = tmp_path / "old"
    shutil.copytree(calibrated, old)
    paths = sorted(old.rglob("certificate.json"))
    assert len(paths) == 2
    for path in paths:
        cert = json.loads(path.read_text(encoding="utf-8"))
        del cert["run"]
        del cert["integrity"]  # neither had a digest then
        path.write_text(json.dumps(cert), encoding="utf-8")
    store = open_store(store_url)
    older = min(paths, key=_started)
    (single,) = ingest_tree(store, older)  # one file
    assert single.new
    done = ingest_tree(store, old / SERIAL)  # one serial's folder, oldest first
    assert [d.new for d in done] == [False, True]
    assert done[0].certificate_id == single.certificate_id
    again = ingest_tree(store, old)  # the folder of serials: nothing new
    assert [d.new for d in again] == [False, False]
    assert [d.run_id for d in again] == [d.run_id for d in done]
    first, second = history(store, SERIAL)
    assert (first.attempt, second.attempt) == (1, 2)
    assert first.started_at < second.started_at
    assert first.station == "(not recorded)"
    assert _counts(store_url)["runs"] == 2
    store.close()


def _started(path: Path) -> str:
    return str(json.loads(path.read_text(encoding="utf-8"))["dates"]["calibration_started"])


def test_a_broken_certificate_is_one_clear_error_and_stores_nothing(
    store_url: str, calibrated: Path, tmp_path: Path
) -> None:
    cert = json.loads((calibrated / SERIAL / "certificate.json").read_text(encoding="utf-8"))
    del cert["results"][1]["expanded_uncertainty"]
    bad = tmp_path / "certificate.json"
    bad.write_text(json.dumps(cert), encoding="utf-8")
    store = open_store(store_url)
    with pytest.raises(InputError, match=r"certificate.json: results\[.*expanded_unc"):
        ingest_certificate(store, bad)
    bad.write_text("{", encoding="utf-8")
    with pytest.raises(InputError, match="not valid JSON"):
        ingest_certificate(store, bad)
    assert _counts(store_url)["runs"] == 0
    store.close()


def test_result_series_filters_station_time_aborted_and_reference(
    store_url: str, calibrated: Path
) -> None:
    text = (calibrated / SERIAL / "certificate.json").read_text(encoding="utf-8")
    store = open_store(store_url)
    plan = [  # (serial, minutes later, run block overrides)
        ("U-1", 0, {"station": "ST-1"}),
        ("U-2", 10, {"station": "ST-2"}),
        ("U-3", 20, {"station": "ST-1", "aborted": True}),
        ("GOLD", 30, {"station": "ST-1", "reference": True}),
        ("U-4", 40, {"station": "ST-2"}),
    ]
    for serial, minutes, overrides in plan:
        ingest_text(store, variant(text, serial=serial, index=minutes, **overrides),
                    source=f"{serial}/certificate.json")
    serials = [p.serial for p in result_series(store, "inertia_kg_m2")]
    assert serials == ["U-1", "U-2", "U-4"]  # oldest first, no aborted, no reference
    assert [p.serial for p in result_series(store, "inertia_kg_m2", include_aborted=True,
                                            include_reference=True)] == \
        ["U-1", "U-2", "U-3", "GOLD", "U-4"]
    assert [p.serial for p in result_series(store, "inertia_kg_m2", station="ST-2")] == \
        ["U-2", "U-4"]
    first = result_series(store, "inertia_kg_m2")[0]
    since = first.started_at + timedelta(minutes=5)
    assert [p.serial for p in result_series(store, "inertia_kg_m2", since=since)] == \
        ["U-2", "U-4"]
    gold = result_series(store, "inertia_kg_m2", include_reference=True, station="ST-1")[-1]
    assert gold.is_reference
    assert gold.serial == "GOLD"
    expected = next(r for r in json.loads(text)["results"] if r["parameter"] == "inertia_kg_m2")
    assert (first.value, first.standard_uncertainty, first.expanded_uncertainty) == (
        expected["value"], expected["standard_uncertainty"], expected["expanded_uncertainty"])
    assert (first.unit, first.nominal, first.lower_limit, first.upper_limit, first.outcome) == (
        expected["unit"], expected["nominal"], expected["lower_limit"],
        expected["upper_limit"], expected["outcome"])
    assert first.started_at.tzinfo is not None
    assert result_series(store, "no_such_result") == []
    assert [u.serial for u in units(store)] == ["GOLD", "U-1", "U-2", "U-3", "U-4"]
    every = run_summaries(store)
    assert [(r.serial, r.aborted, r.is_reference) for r in every] == [
        ("U-1", False, False), ("U-2", False, False), ("U-3", True, False),
        ("GOLD", False, True), ("U-4", False, False)]
    assert [r.serial for r in run_summaries(store, station="ST-2", since=since)] == \
        ["U-2", "U-4"]
    store.close()


def test_baselines_are_saved_replaced_and_loaded(store_url: str) -> None:
    store = open_store(store_url)
    assert load_baseline(store, "inertia_kg_m2") is None
    save_baseline(store, "inertia_kg_m2", {"centre": 0.0036, "runs": ["a", "b"]})
    save_baseline(store, "inertia_kg_m2", {"centre": 0.0037, "runs": ["c"]})
    assert load_baseline(store, "inertia_kg_m2") == {"centre": 0.0037, "runs": ["c"]}
    store.close()
