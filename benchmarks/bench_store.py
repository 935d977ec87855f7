"""Results store benchmark: ingest throughput and the fleet queries over 100 000 runs.

1. Ingest: real certificates (one demo calibration, each copy with its own certificate id)
   stored one by one, each in its own transaction, as ``calibrate`` stores a run: runs/s
   into SQLite (WAL file) and PostgreSQL (a temporary local server, fsync off as in the
   tests; a production server with fsync on is slower per commit).
2. Load: synthetic runs (the certificate's rows with values scattered, 1–3 runs per unit,
   6 stations, a year of dates) bulk-inserted up to ``--runs`` runs, then each fleet query
   timed (median of ``--repeat``): ``units``, ``history SERIAL``, ``trend PARAM`` (all
   runs, and one station since a date) and ``result_series``.

Not a timed test: ``python -m benchmarks.bench_store [--runs 100000] [--ingest 300]``.
"""

from __future__ import annotations

import argparse
import json
import random
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from sqlalchemy import insert

from hil.store import open_store, result_series
from hil.store.engine import Store
from hil.store.ingest import ingest_text
from hil.store.query import history, units
from hil.store.rows import certificate_rows
from hil.store.schema import protocol_outcomes, recordings, results, runs
from tests.store.pg_server import NoServerError, temporary_server

STATIONS = [f"ST-{i}" for i in range(1, 7)]
BATCH_RUNS = 2000


def calibrated_certificate(directory: Path) -> str:
    """One demo calibration (every protocol of the elevation demo), its certificate text."""
    subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--drive", "sim", "--unit-serial",
         "BENCH-0001", "--out", str(directory), "--store", "off"],
        check=True, capture_output=True,
    )
    return (directory / "BENCH-0001" / "certificate.json").read_text(encoding="utf-8")


def copy_of(text: str, index: int) -> str:
    cert = json.loads(text)
    cert["certificate_id"] = f"BENCH-{index:06d}-{uuid.uuid4().hex[:8]}"
    cert["unit"]["serial"] = f"BENCH-{index:06d}"
    cert["run"]["id"] = str(uuid.uuid4())
    return json.dumps(cert)


def ingest_rate(store: Store, text: str, count: int) -> float:
    """Runs per second, one transaction per run."""
    copies = [copy_of(text, i) for i in range(count)]
    started = time.perf_counter()
    for i, copy in enumerate(copies):
        ingest_text(store, copy, source=f"bench/{i}/certificate.json")
    return count / (time.perf_counter() - started)


def synthetic_rows(text: str, total: int, seed: int) -> Iterator[tuple[list[dict[str, Any]],
                                                                     ...]]:
    """Batches of (runs, protocols, results, recordings) rows for ``total`` runs."""
    rng = random.Random(seed)
    template = certificate_rows(text, source="synthetic")
    start = datetime(2026, 1, 1, tzinfo=UTC)
    made, unit = 0, 0
    while made < total:
        batch: tuple[list[dict[str, Any]], ...] = ([], [], [], [])
        while len(batch[0]) < BATCH_RUNS and made < total:
            unit += 1
            for attempt in range(1, min(rng.choice((1, 1, 1, 2, 2, 3)), total - made) + 1):
                run_id = str(uuid.uuid4())
                moment = start + timedelta(minutes=rng.uniform(0, 525_600))
                batch[0].append(dict(
                    template.run, run_id=run_id, certificate_id=f"SYN-{made:07d}",
                    serial=f"SYN-{unit:06d}", station=rng.choice(STATIONS), attempt=attempt,
                    started_at=moment, ended_at=moment + timedelta(seconds=90),
                    is_reference=unit % 500 == 0, aborted=rng.random() < 0.01,
                    ingested_at=moment, outcome="PASS"))
                batch[1].extend(dict(p, run_id=run_id) for p in template.protocols)
                batch[2].extend(
                    dict(r, run_id=run_id,
                         value=r["value"] + rng.gauss(0, r["standard_uncertainty"]))
                    for r in template.results)
                batch[3].extend(dict(f, run_id=run_id) for f in template.recordings)
                made += 1
        yield batch


def load(store: Store, text: str, total: int) -> float:
    started = time.perf_counter()
    for batch in synthetic_rows(text, total, seed=2026):
        with store.engine.begin() as connection:
            for table, rows in zip((runs, protocol_outcomes, results, recordings), batch,
                                   strict=True):
                connection.execute(insert(table), rows)
    return time.perf_counter() - started


def timed(function: Callable[[], object], repeat: int) -> tuple[float, int]:
    times, size = [], 0
    for _ in range(repeat):
        started = time.perf_counter()
        found = function()
        times.append(time.perf_counter() - started)
        size = len(found) if isinstance(found, list) else 0
    return statistics.median(times), size


def bench(url: str, text: str, args: argparse.Namespace) -> list[tuple[str, str]]:
    store = open_store(url)
    rate = ingest_rate(store, text, args.ingest)
    rows = [("ingest, one transaction per run", f"{rate:.0f} runs/s")]
    seconds = load(store, text, args.runs - args.ingest)
    rows.append((f"bulk load to {args.runs} runs", f"{seconds:.0f} s"))
    since = datetime(2026, 10, 1, tzinfo=UTC)
    queries: list[tuple[str, Callable[[], object]]] = [
        ("`results units` (every unit's last run)", lambda: units(store)),
        ("`results history SERIAL`", lambda: history(store, "SYN-000042")),
        ("`result_series(inertia_kg_m2)` (all runs)",
         lambda: result_series(store, "inertia_kg_m2")),
        ("`results trend inertia_kg_m2 --station ST-3 --since 2026-10-01`",
         lambda: result_series(store, "inertia_kg_m2", station="ST-3", since=since)),
    ]
    for name, query in queries:
        seconds, size = timed(query, args.repeat)
        rows.append((name, f"{seconds * 1000:.0f} ms ({size} rows)"))
    rows.append(("database size", f"{database_bytes(store) / 1e9:.2f} GB"))
    store.close()
    return rows


def database_bytes(store: Store) -> int:
    with store.engine.connect() as connection:
        if store.dialect == "postgresql":
            return int(connection.exec_driver_sql(
                "SELECT pg_database_size(current_database())").scalar_one())
        database = connection.engine.url.database or ""
    return sum(p.stat().st_size for p in Path(database).parent.glob("results.sqlite*"))


@contextmanager
def postgres_url() -> Iterator[str | None]:
    try:
        with temporary_server() as server:
            yield server.create_database()
    except NoServerError as exc:
        print(f"PostgreSQL skipped: {exc}", file=sys.stderr)
        yield None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=100_000)
    parser.add_argument("--ingest", type=int, default=300)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        text = calibrated_certificate(Path(tmp))
        table = {"SQLite": bench(f"sqlite:///{tmp}/results.sqlite", text, args)}
        with postgres_url() as url:
            if url is not None:
                table["PostgreSQL"] = bench(url, text, args)
    results_per_run = len(json.loads(text)["results"])
    print(f"{args.runs} runs, {results_per_run} results each\n")
    names = list(table)
    print("| what | " + " | ".join(names) + " |")
    print("|---|" + "---|" * len(names))
    for i, (what, _) in enumerate(table["SQLite"]):
        print(f"| {what} | " + " | ".join(table[n][i][1] for n in names) + " |")


if __name__ == "__main__":
    main()
