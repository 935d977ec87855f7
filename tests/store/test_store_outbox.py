"""The server stops during a calibration: the run is written, keeps its outcome, waits in
the outbox, and ``gimbal-hil results sync`` uploads it once the server is back: nothing
lost, nothing stored twice. The store is chosen by the station file's ``[station]`` table."""

from __future__ import annotations

import json
from pathlib import Path

# loaded before pytester's in-process runs snapshot sys.modules (numpy's fft loads once)
import gimbal_hil_protocols.test_inertia_friction  # noqa: F401
import pytest
from pg_server import PostgresServer

from hil.cli import main
from hil.store import open_store
from hil.store.outbox import pending
from hil.store.query import history
from tests.helpers import subset_profile

pytest_plugins = ["pytester"]


class StopServerAtFirstProtocol:
    """Stops the server when the first protocol test starts: mid-run, after pytest began."""

    def __init__(self, server: PostgresServer) -> None:
        self.server = server
        self.stopped = False

    def pytest_runtest_setup(self, item: pytest.Item) -> None:
        if not self.stopped:
            self.server.stop()
            self.stopped = True


def _calibrate(pytester: pytest.Pytester, out: Path, station: Path, *args: str,
               plugins: tuple[object, ...] = ()) -> pytest.RunResult:
    return pytester.runpytest_inprocess(
        "--profile", str(subset_profile(pytester.path, "inertia_friction")),
        "--pyargs", "gimbal_hil_protocols.test_inertia_friction", "-p", "no:cacheprovider",
        "--out", str(out), "--unit-serial", "OUT-1", "--station", str(station), *args,
        plugins=list(plugins),
    )


def test_a_server_outage_during_a_run_loses_nothing(
    pytester: pytest.Pytester, postgres: PostgresServer, tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    url = postgres.create_database().replace("postgresql+psycopg://", "postgresql://")
    station = tmp_path / "station.toml"
    station.write_text(f'[station]\nid = "ST-7"\nstore = "{url}"\n', encoding="utf-8")
    out = tmp_path / "certs"

    first = _calibrate(pytester, out, station)
    assert first.ret == 0
    first.stdout.fnmatch_lines(["results store: run * stored in postgresql+psycopg://*"])

    stopper = StopServerAtFirstProtocol(postgres)
    try:
        second = _calibrate(pytester, out, station, "--reference", "--operator", "alice",
                            plugins=(stopper,))
    finally:
        if stopper.stopped:
            postgres.start()
    assert stopper.stopped
    assert second.ret == 0  # the run's outcome is not the store's to change
    second.stdout.fnmatch_lines(["results store UNREACHABLE (*); run kept in the outbox *"])
    certificate = json.loads((out / "OUT-1" / "certificate.json").read_text(encoding="utf-8"))
    assert certificate["outcome"] == "PASS"
    assert certificate["run"]["station"] == "ST-7"
    (entry,) = pending(out)
    assert entry.name == f"{certificate['certificate_id']}.json"

    capsys.readouterr()
    assert main(["results", "sync", "--out", str(out), "--station-file", str(station),
                 "--json"]) == 0
    synced = json.loads(capsys.readouterr().out)
    assert (synced["new"], synced["already_stored"]) == (1, 0)
    assert pending(out) == []
    assert main(["results", "sync", "--out", str(out), "--station-file", str(station)]) == 0
    assert "sync: 0 run(s) stored, 0 already stored" in capsys.readouterr().out
    assert main(["results", "ingest", str(out), "--station-file", str(station), "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert (again["new"], again["already_stored"]) == (0, 2)

    store = open_store(url)
    runs = history(store, "OUT-1")
    store.close()
    written = [json.loads(p.read_text(encoding="utf-8"))["certificate_id"]
               for p in sorted((out / "OUT-1" / "history").glob("*/certificate.json"))]
    assert [r.certificate_id for r in runs] == [*written, certificate["certificate_id"]]
    assert [r.attempt for r in runs] == [1, 2]
    assert {r.station for r in runs} == {"ST-7"}
    assert [(r.operator, r.is_reference) for r in runs][1] == ("alice", True)
    assert runs[0].is_reference is False
