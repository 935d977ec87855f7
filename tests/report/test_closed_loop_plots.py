"""A plot and a caption for every protocol of the suite; the closed-loop protocols' plots
drawn from a simulated calibration's certificate and recordings, each checked against the
results it shows, its labels carrying units and its legends off the data."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.legend import Legend
from matplotlib.patches import Rectangle

from hil.config import read_toml
from hil.plugin import protocols_dir
from hil.profile import builtin_profile_path
from hil.report.data import ProtocolData, from_certificate
from hil.report.figures import png_bytes
from hil.report.plots import CAPTIONS, PLOTTERS, protocol_figure
from hil.suite.cogging_compensation import CoggingCompensationDetails
from hil.suite.velocity_loop_frf import VelocityLoopFrfDetails
from hil.suite.velocity_step import VelocityStepDetails
from tests.helpers import subset_profile
from tests.report.runs import Run

CLOSED_LOOP = ("velocity_loop_frf", "velocity_step", "tracking", "standstill",
               "cogging_compensation")
UNIT = re.compile(r"\(.+\)$")  # "torque (N·m)", "(v − v₀) / Δ (1)"


def suite_protocols() -> set[str]:
    """Every protocol the suite holds (``protocols/test_<name>.py``) or a demo unit runs."""
    names = {path.stem.removeprefix("test_") for path in protocols_dir().glob("test_*.py")}
    for profile in ("demo_gimbal_elevation", "demo_gimbal_azimuth"):
        names |= set(read_toml(builtin_profile_path(profile))[0]["protocols"])
    return names


def test_every_protocol_in_the_suite_has_a_plot_and_a_caption() -> None:
    names = suite_protocols()
    assert set(CLOSED_LOOP) <= names
    assert sorted(names - set(PLOTTERS)) == [], "protocols without a plot"
    assert sorted(n for n in names if not CAPTIONS.get(n, "").strip()) == [], \
        "protocols without a caption"


@pytest.fixture(scope="module")
def closed_loop(elevation_run: Run) -> dict[str, ProtocolData]:
    cert = json.loads((elevation_run.unit_dir / "certificate.json").read_text(encoding="utf-8"))
    return {d.name: d for d in from_certificate(cert, elevation_run.unit_dir)
            if d.name in CLOSED_LOOP}


def drawn(data: ProtocolData) -> Figure:
    fig = protocol_figure(data)
    assert fig is not None, f"no plot of {data.name}"
    assert png_bytes(fig)[:8] == b"\x89PNG\r\n\x1a\n"
    return fig


def legends_on_axes(fig: Figure) -> int:
    """Legends (the figure's and the axes') whose box overlaps any axes: the data's area."""
    renderer = FigureCanvasAgg(fig).get_renderer()  # type: ignore[no-untyped-call]
    fig.draw(renderer)
    plots = [ax.get_window_extent(renderer) for ax in fig.axes]
    legends: list[Legend] = [*fig.legends]
    legends += [legend for ax in fig.axes if (legend := ax.get_legend()) is not None]
    assert legends, "no legend"
    return sum(any(legend.get_window_extent(renderer).overlaps(p) for p in plots)
               for legend in legends)


@pytest.mark.parametrize("name", CLOSED_LOOP)
def test_closed_loop_plot_has_data_units_and_legends_off_it(
        name: str, closed_loop: dict[str, ProtocolData]) -> None:
    fig = drawn(closed_loop[name])
    assert legends_on_axes(fig) == 0, f"{name}: a legend on the data"
    for ax in fig.axes:
        assert ax.lines or ax.patches or ax.collections, f"{name}: empty axes"
        assert UNIT.search(ax.get_ylabel()), f"{name}: y label {ax.get_ylabel()!r} has no unit"
        if ax.get_xlabel():
            assert UNIT.search(ax.get_xlabel()), f"{name}: x label {ax.get_xlabel()!r}"
    assert any(ax.get_xlabel() for ax in fig.axes)


def test_velocity_loop_frf_plot_marks_bandwidth_and_margins(
        closed_loop: dict[str, ProtocolData]) -> None:
    data = closed_loop["velocity_loop_frf"]
    fig = drawn(data)
    details = data.details_as(VelocityLoopFrfDetails)
    assert details is not None
    lines = len(details.frequencies_hz)
    assert [sum(np.size(line.get_xdata()) == lines for line in ax.lines) for ax in fig.axes] \
        == [2, 1, 1, 1]  # |T| and |S|; |L|; ∠T; ∠L
    titles = " ".join(ax.get_title() for ax in fig.axes)
    for parameter, unit in (("velocity_bandwidth_hz", " Hz"), ("velocity_gain_margin_db", " dB"),
                            ("velocity_phase_margin_deg", "°")):
        assert f"{data.value(parameter):.3g}{unit}" in titles, parameter


def test_velocity_step_plot_draws_every_step_with_its_rise(
        closed_loop: dict[str, ProtocolData]) -> None:
    data = closed_loop["velocity_step"]
    fig = drawn(data)
    details = data.details_as(VelocityStepDetails)
    assert details is not None
    for ax, size in zip(fig.axes, ("small", "large"), strict=True):
        mine = [s for s in details.steps if s.size == size]
        traces = [line for line in ax.lines if "rotation" in str(line.get_label())]
        assert len(traces) == len(mine) == 4
        crossings = [np.asarray(line.get_xdata(), dtype=float) for line in ax.lines
                     if line.get_marker() == "|"]
        rises_ms = [float(x[1] - x[0]) for x in crossings]
        assert rises_ms == pytest.approx([1e3 * s.rise_time_s for s in mine], rel=1e-4)


def test_tracking_plot_draws_the_error_the_results_measure(
        closed_loop: dict[str, ProtocolData]) -> None:
    data = closed_loop["tracking"]
    (off, on) = (line for line in drawn(data).axes[0].lines if "feedforward" in
                 str(line.get_label()))
    for line, parameter in ((off, "tracking_rms_error_no_ff_urad"),
                            (on, "tracking_rms_error_urad")):
        rms = float(np.sqrt(np.mean(np.asarray(line.get_ydata()) ** 2)))
        assert rms == pytest.approx(data.value(parameter), rel=0.01), parameter


def test_standstill_plot_draws_what_its_rms_is_taken_of(
        closed_loop: dict[str, ProtocolData]) -> None:
    data = closed_loop["standstill"]
    left, right = drawn(data).axes
    for ax, parameter in ((left, "standstill_jitter_urad"),
                          (right, "standstill_torque_ripple_mnm")):
        rms = float(np.sqrt(np.mean(np.asarray(ax.lines[0].get_ydata()) ** 2)))
        assert rms == pytest.approx(data.value(parameter), rel=0.05), parameter


def test_cogging_compensation_plot_shows_the_ripple_cleared_and_loaded(
        closed_loop: dict[str, ProtocolData]) -> None:
    data = closed_loop["cogging_compensation"]
    left, right = drawn(data).axes
    details = data.details_as(CoggingCompensationDetails)
    assert details is not None
    orders = details.orders
    heights = np.array([p.get_height() for p in right.patches if isinstance(p, Rectangle)]
                       ).reshape(2, len(orders))
    assert heights.max(axis=1) == pytest.approx(
        [data.value("cogging_ripple_uncompensated_urad"),
         data.value("cogging_ripple_compensated_urad")], rel=1e-3)
    assert len(left.lines) == 4  # bin means and fitted orders, cleared and loaded


def test_allure_gets_a_closed_loop_protocols_plot(tmp_path: Path) -> None:
    pytest.importorskip("allure_pytest")
    allure_dir = tmp_path / "allure"
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", "--pyargs",
         "gimbal_hil_protocols.test_standstill", "--out", str(tmp_path / "certs"),
         "--profile", str(subset_profile(tmp_path, "standstill")), "--store", "off",
         "--no-documents", "--alluredir", str(allure_dir)],
        capture_output=True, text=True, timeout=600, check=False, cwd=tmp_path,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    attached = {a["name"]: allure_dir / a["source"]
                for container in allure_dir.glob("*-container.json")
                for step in json.loads(container.read_text()).get("afters", [])
                for a in step.get("attachments", [])}
    assert "standstill.png" in attached, sorted(attached)
    assert attached["standstill.png"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
