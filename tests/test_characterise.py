"""``gimbal-hil characterise``: a user builds the method-bias map of a unit type.

A small unit type (the J/B/T_c sines alone) and two drawn units: the map it writes holds a
line per result; the same options again resume (nothing is calibrated twice); other
options on the same folder are refused in one line before anything runs; the map does not
depend on ``--jobs``.
"""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from tests.helpers import subset_profile

pytestmark = pytest.mark.slow(seconds=55)


def _characterise(out: Path, profile: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "hil.cli", "characterise", "--profile", str(profile),
         "--units", "2", "--seed", "5", "--method-bias", "off", "--out", str(out), *extra],
        capture_output=True, text=True, check=False, timeout=900)


@pytest.fixture(scope="module")
def profile(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return subset_profile(tmp_path_factory.mktemp("type"), "inertia_friction")


def test_a_map_is_written_resumed_and_independent_of_the_jobs(
        profile: Path, tmp_path: Path) -> None:
    first = _characterise(tmp_path / "one", profile, "--jobs", "1",
                          "--write-map", str(tmp_path / "one.toml"))
    assert first.returncode == 0, first.stderr
    assert first.stdout.count("results (") == 2  # a progress line per unit
    document = tomllib.loads((tmp_path / "one.toml").read_text(encoding="utf-8"))
    lines = document["results"]["elevation"]
    assert set(lines) == {"inertia_kg_m2", "viscous_nm_s_rad", "coulomb_nm"}
    assert all(line["units"] == 2 and line["scatter"] >= 0 for line in lines.values())

    stamps = {p: p.stat().st_mtime_ns for p in (tmp_path / "one").rglob("certificate.json")}
    again = _characterise(tmp_path / "one", profile, "--jobs", "1")
    assert again.returncode == 0, again.stderr
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps  # read back, not calibrated

    both = _characterise(tmp_path / "two", profile, "--jobs", "2",
                         "--write-map", str(tmp_path / "two.toml"))
    assert both.returncode == 0, both.stderr
    assert tomllib.loads((tmp_path / "two.toml").read_text(encoding="utf-8"))[
        "results"] == document["results"]


def test_other_options_on_a_population_folder_are_refused_before_any_run(
        profile: Path, tmp_path: Path) -> None:
    (tmp_path / "pop").mkdir()
    (tmp_path / "pop" / "population.toml").write_text(
        'profiles = ["x.toml"]\nunits_per_profile = 3\nseed = 5\nmethod_bias = "off"\n',
        encoding="utf-8")
    refused = _characterise(tmp_path / "pop", profile)
    assert refused.returncode == 2
    assert refused.stderr.count("\n") == 1
    assert "units_per_profile 3 → 2" in refused.stderr
    assert not (tmp_path / "pop" / "units").exists()


def test_a_population_on_a_dask_cluster_gives_the_map_of_the_local_run(
        profile: Path, tmp_path: Path) -> None:
    """The cluster's scheduler and worker in this process (loopback, threads); the command
    connects to it as it would to a cluster's, and each unit still runs in its own process."""
    from distributed import LocalCluster

    local = _characterise(tmp_path / "local", profile, "--jobs", "2",
                          "--write-map", str(tmp_path / "local.toml"))
    assert local.returncode == 0, local.stderr
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                      protocol="tcp", host="127.0.0.1", scheduler_port=0,
                      dashboard_address=None) as cluster:
        remote = _characterise(tmp_path / "cluster", profile, "--scheduler",
                               cluster.scheduler_address,
                               "--write-map", str(tmp_path / "cluster.toml"))
    assert remote.returncode == 0, remote.stderr
    assert f"on the cluster at {cluster.scheduler_address}" in remote.stdout
    assert remote.stdout.count("results (") == 2
    maps = [tomllib.loads((tmp_path / f"{name}.toml").read_text(encoding="utf-8"))["results"]
            for name in ("local", "cluster")]
    assert maps[0] == maps[1]


@pytest.mark.parametrize(("address", "named"), [("tcp://127.0.0.1:9", "127.0.0.1:9"),
                                              ("nonsense", "tcp://HOST:PORT")])
def test_an_unreachable_or_malformed_scheduler_is_one_line(
        profile: Path, tmp_path: Path, address: str, named: str) -> None:
    refused = _characterise(tmp_path / "pop", profile, "--scheduler", address)
    assert refused.returncode == 2
    assert refused.stderr.count("\n") == 1, refused.stderr
    assert "--scheduler" in refused.stderr
    assert named in refused.stderr
