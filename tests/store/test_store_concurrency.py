"""Eight stations storing at once into one store (PostgreSQL and SQLite) lose nothing and
duplicate nothing.

What the eight processes do: each stores runs exactly as ``calibrate`` does after writing a
certificate (:func:`hil.store.record.record_run`: open the store, migrating a new one, then
ingest), all released at the same instant by a barrier, into a store none of them created.
The certificates are real (from one simulated calibration) with distinct ids, rather than
eight full calibrations: the store sees the same rows, at a fraction of the CPU. One
certificate is stored by all eight at once (a station retrying, a sync racing a run).
"""

from __future__ import annotations

import json
import multiprocessing
from multiprocessing.synchronize import Barrier
from pathlib import Path
from typing import Any

from sqlalchemy import func, select
from store_variants import SERIAL, copy_files, variant

from hil.store import open_store
from hil.store.outbox import pending
from hil.store.record import record_run
from hil.store.schema import recordings, results, runs

STATIONS = 8
RUNS_EACH = 5


def _station(url: str, paths: list[Path], out_dir: Path, barrier: Barrier,
             messages: Any) -> None:
    barrier.wait()
    for path in paths:
        messages.put(record_run(path, out_dir=out_dir, url=url))


def test_eight_stations_at_once_lose_and_duplicate_nothing(
    store_url: str, calibrated: Path, tmp_path: Path
) -> None:
    text = (calibrated / SERIAL / "certificate.json").read_text(encoding="utf-8")
    shared = tmp_path / "shared" / "certificate.json"
    shared.parent.mkdir()
    shared.write_text(variant(text, serial="SHARED", index=0, files=True), encoding="utf-8")
    copy_files(shared, calibrated / SERIAL)
    plans: list[list[Path]] = []
    for station in range(STATIONS):
        paths = []
        for k in range(RUNS_EACH):
            path = tmp_path / f"st{station}" / f"U{station}-{k}" / "certificate.json"
            path.parent.mkdir(parents=True)
            path.write_text(variant(text, serial=f"U{station}-{k}", index=k, files=True,
                                    station=f"ST-{station}"), encoding="utf-8")
            copy_files(path, calibrated / SERIAL)
            paths.append(path)
        paths.insert(station % RUNS_EACH, shared)
        plans.append(paths)

    context = multiprocessing.get_context("fork")
    barrier = context.Barrier(STATIONS)
    messages = context.Queue()
    workers = [
        context.Process(target=_station,
                        args=(store_url, plans[i], tmp_path / f"st{i}", barrier, messages))
        for i in range(STATIONS)
    ]
    for worker in workers:
        worker.start()
    said = [messages.get() for _ in range(STATIONS * (RUNS_EACH + 1))]
    for worker in workers:
        worker.join()
    assert [w.exitcode for w in workers] == [0] * STATIONS
    not_stored = [m for m in said if not m.startswith("results store: run ")]
    assert not not_stored, "\n".join(not_stored)
    assert not any(pending(tmp_path / f"st{i}") for i in range(STATIONS))

    store = open_store(store_url)
    with store.engine.connect() as connection:
        ids = list(connection.execute(select(runs.c.certificate_id)).scalars())
        result_rows = connection.execute(select(func.count()).select_from(results)).scalar()
        file_rows = connection.execute(select(func.count()).select_from(recordings)).scalar()
    store.close()
    expected = {json.loads(p.read_text(encoding="utf-8"))["certificate_id"]
                for plan in plans for p in plan}
    assert len(ids) == len(set(ids)) == STATIONS * RUNS_EACH + 1
    assert set(ids) == expected
    per_run_results = text.count('"parameter":')
    assert result_rows == len(ids) * per_run_results
    assert file_rows == len(ids) * text.count('"excitation":')
