"""A gimbal in the store: its certificate's row (part number, revision, one verdict over
its axes' runs) beside the axes' runs, on SQLite and PostgreSQL; ingested with a tree,
idempotent, refused when an axis's certificate is not the one it records."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from hil.errors import InputError
from hil.store import ingest_certificate, open_store
from hil.store.ingest import ingest_tree
from hil.store.query import gimbal_identities, units

SERIAL = "GMB-S1"


@pytest.fixture(scope="module")
def gimbal_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``--out`` of one simulated gimbal calibration (the current-loop protocol of each
    axis), stored nowhere."""
    out = tmp_path_factory.mktemp("gimbal")
    done = subprocess.run(
        [sys.executable, "-m", "hil.cli", "calibrate", "--gimbal", "demo_gimbal", "--drive",
         "sim", "--unit-serial", SERIAL, "--out", str(out), "--store", "off", "--", "-k",
         "current_loop", "--no-documents"], capture_output=True, text=True, check=False,
        timeout=600)
    assert (out / SERIAL / "gimbal-certificate.json").is_file(), done.stdout + done.stderr
    return out


def test_a_gimbal_is_stored_with_its_part_number_beside_its_axes_runs(
    store_url: str, gimbal_out: Path
) -> None:
    store = open_store(store_url)
    try:
        done = ingest_tree(store, gimbal_out)
        assert sorted(d.new for d in done) == [True, True, True]  # two axes, one gimbal
        assert gimbal_identities(store) == {SERIAL: ("GMB-2", "B")}
        (unit,) = units(store)
        assert (unit.serial, unit.axis) == (SERIAL, "azimuth, elevation")
        again = ingest_certificate(store, gimbal_out / SERIAL / "gimbal-certificate.json")
        assert not again.new
    finally:
        store.close()


def test_a_gimbal_certificate_whose_axis_changed_is_refused(
    tmp_path: Path, gimbal_out: Path
) -> None:
    folder = tmp_path / SERIAL
    subprocess.run(["cp", "-r", str(gimbal_out / SERIAL), str(folder)], check=True)
    document = json.loads((folder / "gimbal-certificate.json").read_text(encoding="utf-8"))
    document["axes"][1]["certificate_sha256"] = "0" * 64
    (folder / "gimbal-certificate.json").write_text(json.dumps(document), encoding="utf-8")
    store = open_store(f"sqlite:///{tmp_path / 'results.sqlite'}")
    try:
        with pytest.raises(InputError, match=r"axis elevation: its certificate "
                                              r"elevation/GMB-S1/certificate\.json is not the "
                                              r"one this gimbal certificate records"):
            ingest_certificate(store, folder / "gimbal-certificate.json")
        assert gimbal_identities(store) == {}
    finally:
        store.close()
