"""The places one protocol lives in agree with the catalogue (``hil.suite.catalogue``):
its pytest module, its planned motion, its plot and caption, its title on the certificate,
the results the demo profiles declare, the method-bias map and the repeatability map. A
protocol added in its suite module but forgotten in one of them fails here, naming it
(docs/contributing.md lists the files)."""

from __future__ import annotations

import importlib
import tomllib
from pathlib import Path

import pytest

from hil.certificate.render import PROTOCOL_TITLES
from hil.profile import load_profile
from hil.report.plots import CAPTIONS, PLOTTERS
from hil.suite.catalogue import CATALOGUE, PROTOCOL_OF, PROTOCOLS, check_profile
from tests.helpers import drive_info

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", sorted(PROTOCOLS))
def test_every_protocol_has_its_test_plan_plot_and_title(name: str) -> None:
    module = importlib.import_module(f"gimbal_hil_protocols.test_{name}")
    assert set(module.DECLARED) == set(PROTOCOLS[name]), "declared ≠ the suite's MEASUREMENTS"
    assert CATALOGUE[name].name == name, "PROTOCOL.name ≠ its catalogue key"
    assert name in PROTOCOL_TITLES, "no title (hil/certificate/render.py PROTOCOL_TITLES)"
    assert name in PLOTTERS, "no plot (hil/report/plots.py PLOTTERS)"
    assert name in CAPTIONS, "no caption (hil/report/plots.py CAPTIONS)"


def test_nothing_outside_the_catalogue_is_planned_plotted_or_titled() -> None:
    for table, where in ((PLOTTERS, "PLOTTERS"), (CAPTIONS, "CAPTIONS"),
                         (PROTOCOL_TITLES, "PROTOCOL_TITLES")):
        assert set(table) <= set(PROTOCOLS), f"{where}: {set(table) - set(PROTOCOLS)}"


@pytest.mark.parametrize("profile", ["demo_gimbal_elevation", "demo_gimbal_azimuth"])
def test_a_demo_profile_declares_only_what_its_protocols_measure(profile: str) -> None:
    check_profile(load_profile(profile))  # raises, naming the table


def test_every_protocol_plans_its_motion_on_a_demo_profile_that_configures_it() -> None:
    """Each PROTOCOL's planned motion builds from the profile alone (the planner would log
    a failure at DEBUG and plan nothing); cogging plans none: it analyses the gravity
    protocol's sweeps."""
    planned: dict[str, float] = {}
    for name in ("demo_gimbal_elevation", "demo_gimbal_azimuth"):
        profile = load_profile(name)
        info = drive_info(profile, profile.sample_rate_hz)
        for protocol in (CATALOGUE[p] for p in profile.protocols):
            motion = protocol.planned_motion(profile, info, lambda: 0.0)
            planned[protocol.name] = sum(e.duration_s for e in motion)
    assert set(planned) == set(CATALOGUE)
    assert {name for name, seconds in planned.items() if seconds <= 0} == {"cogging"}


@pytest.mark.parametrize("path", ["fixtures/method_bias.toml",
                                  "fixtures/compare_repeatability.toml"])
def test_the_maps_name_only_results_the_catalogue_knows(path: str) -> None:
    document = tomllib.loads((ROOT / path).read_text(encoding="utf-8"))
    for axis, results in document["results"].items():
        unknown = set(results) - set(PROTOCOL_OF)
        assert not unknown, f"{path} [{axis}]: {unknown}"
