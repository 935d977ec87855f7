"""The station file's ``[station]`` table: id, results store, reference; checked like every
other table (unknown key or wrong type: one error naming file, table and key). The store's
choice, and a bad outbox entry."""

from __future__ import annotations

from pathlib import Path

import pytest
from store_variants import SERIAL

from hil.config import builtin_fixture
from hil.drives.station import CanOpenStation, load_station, load_station_identity
from hil.errors import InputError, ProfileError
from hil.store import open_store
from hil.store.engine import ENV_VAR, resolve_store_url
from hil.store.outbox import outbox_dir, pending, sync_outbox, to_outbox


def test_the_example_station_loads_with_its_station_table() -> None:
    path = builtin_fixture("station_canopen_example.toml")
    assert isinstance(load_station(path), CanOpenStation)
    identity = load_station_identity(path)
    assert (identity.station_id, identity.store, identity.reference) == ("ST-1", None, False)


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ('id = "ST-2"\nstroe = "x"', r"\[station\] has an unknown setting 'stroe' \(did you "
                                      r"mean 'store'\?\)"),
        ("reference = 1", r"\[station\] 'reference': must be true or false"),
        ("id = 3", r"\[station\] 'id': must be a string"),
    ],
)
def test_a_bad_station_table_names_file_table_and_key(tmp_path: Path, table: str,
                                                      message: str) -> None:
    path = tmp_path / "bench.toml"
    path.write_text(f"[station]\n{table}\n", encoding="utf-8")
    with pytest.raises(ProfileError, match=message) as caught:
        load_station_identity(path)
    assert str(path) in str(caught.value)


def test_the_store_is_chosen_option_then_environment_then_station_then_out(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv(ENV_VAR, raising=False)
    station = "postgresql://line@db/gimbal"
    assert resolve_store_url(None, out_dir=tmp_path) == \
        f"sqlite:///{tmp_path.resolve()}/results.sqlite"
    assert resolve_store_url(None, out_dir=tmp_path, station_store=station) == \
        "postgresql+psycopg://line@db/gimbal"
    monkeypatch.setenv(ENV_VAR, "postgres://env@db/gimbal")
    assert resolve_store_url(None, out_dir=tmp_path, station_store=station) == \
        "postgresql+psycopg://env@db/gimbal"
    assert resolve_store_url("sqlite:///x.sqlite", out_dir=tmp_path, station_store=station) \
        == "sqlite:///x.sqlite"
    assert resolve_store_url("my.sqlite", out_dir=tmp_path) == \
        f"sqlite:///{Path('my.sqlite').resolve()}"


def test_a_bad_outbox_entry_is_named_and_the_others_still_sync(
    tmp_path: Path, calibrated: Path
) -> None:
    out = tmp_path / "out"
    to_outbox(out, calibrated / SERIAL / "certificate.json")
    bad = outbox_dir(out) / "broken.json"
    bad.write_text('{"certificate_path": "x", "certificate_text": "{}"}', encoding="utf-8")
    store = open_store(f"sqlite:///{tmp_path / 'results.sqlite'}")
    with pytest.raises(InputError, match=r"broken.json: not an outbox entry .* \(1 synced\)"):
        sync_outbox(store, out)
    store.close()
    assert pending(out) == [bad]
