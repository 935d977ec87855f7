"""The migration path: a store at revision 1 holding runs is brought to head on open and
keeps them; the shipped migrations build exactly the tables the code uses."""

from __future__ import annotations

from pathlib import Path

from alembic.autogenerate import compare_metadata
from alembic.config import Config
from alembic.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import create_engine, inspect, text
from store_variants import SERIAL

from hil.store import ingest_certificate, load_baseline, open_store, result_series, save_baseline
from hil.store.engine import HEAD_REVISION, MIGRATIONS, Store, _engine, parse_store_url, upgrade
from hil.store.schema import metadata


def _revision_1_store(url: str) -> Store:
    engine = _engine(parse_store_url(url))
    upgrade(engine, "0001")
    return Store(engine=engine, url=url)


def test_head_is_the_newest_shipped_migration() -> None:
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    assert ScriptDirectory.from_config(config).get_current_head() == HEAD_REVISION


def test_a_revision_1_store_is_upgraded_and_keeps_its_runs(store_url: str,
                                                          calibrated: Path) -> None:
    old = _revision_1_store(store_url)
    tables = set(inspect(old.engine).get_table_names())
    assert "runs" in tables
    assert "spc_baselines" not in tables  # revision 2 adds it
    path = calibrated / SERIAL / "certificate.json"
    stored = ingest_certificate(old, path)
    before = result_series(old, "inertia_kg_m2")
    old.close()

    store = open_store(store_url)  # upgrades to head
    with store.engine.connect() as connection:
        assert connection.execute(text("SELECT version_num FROM alembic_version")).scalar() \
            == HEAD_REVISION
    assert result_series(store, "inertia_kg_m2") == before
    assert before[0].run_id == stored.run_id
    assert not ingest_certificate(store, path).new  # still the same run
    save_baseline(store, "inertia_kg_m2", {"centre": 1.0})
    assert load_baseline(store, "inertia_kg_m2") == {"centre": 1.0}
    store.close()


def test_the_migrations_build_the_schema_the_code_uses(store_url: str) -> None:
    store = open_store(store_url)
    engine = create_engine(parse_store_url(store_url))
    with engine.connect() as connection:
        differences = compare_metadata(MigrationContext.configure(connection), metadata)
    engine.dispose()
    store.close()
    assert differences == []
