"""PNG figures of the fleet report (matplotlib, Agg backend; imported only for the report).

Sized for e-mail: drawn at 90 dpi and stored with a 16-colour palette (line charts have
few colours; full-colour antialiasing made each chart 3–4 × larger for nothing a reader
sees). Every axis names its quantity and unit; run numbers and counts have integer ticks.
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

from hil.errors import InputError
from hil.fleet.capability import moving_ranges
from hil.fleet.spc import SpcResult

_HIT = "#d62728"
_LIMIT = "#1f77b4"
_SPEC = "#ff7f0e"
DPI = 90
PALETTE_COLOURS = 16


def _pyplot() -> Any:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - matplotlib is an optional extra
        raise InputError("the fleet report needs matplotlib (pip install gimbal-hil[plots])"
                         ) from exc
    return plt


def _ticker() -> Any:
    _pyplot()
    import matplotlib.ticker

    return matplotlib.ticker


def _png(fig: Any) -> bytes:
    """The figure as a palette PNG (:data:`PALETTE_COLOURS` colours, no dithering)."""
    plt = _pyplot()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=DPI)
    plt.close(fig)
    from PIL import Image  # matplotlib's own dependency

    image = Image.open(io.BytesIO(buffer.getvalue())).convert("RGB")
    small = io.BytesIO()
    image.quantize(colors=PALETTE_COLOURS, method=Image.Quantize.MEDIANCUT,
                   dither=Image.Dither.NONE).save(small, format="PNG", optimize=True)
    return small.getvalue()


def axis_label(quantity: str, unit: str) -> str:
    """``quantity [unit]``; a result without a unit says so."""
    return f"{quantity} [{unit}]" if unit else f"{quantity} (no unit)"


def _integer_ticks(axis: Any) -> None:
    """Whole-number ticks only (run numbers, counts)."""
    axis.set_major_locator(_ticker().MaxNLocator(integer=True, min_n_ticks=1))


def _onsets(rule_hits: dict[int, list[int]]) -> dict[int, list[int]]:
    """Where each rule starts firing: the first index of every block of consecutive hits
    (labelling every hit would bury the chart under text)."""
    onsets: dict[int, list[int]] = {}
    for rule, hits in sorted(rule_hits.items()):
        for k, i in enumerate(hits):
            if k == 0 or hits[k - 1] != i - 1:
                onsets.setdefault(i, []).append(rule)
    return onsets


def histogram_png(result: SpcResult) -> bytes:
    """Histogram of the values with the specification limits, nominal and mean (PNG)."""
    return _png(histogram_figure(result))


def histogram_figure(result: SpcResult) -> Any:
    """The histogram's matplotlib figure (the caller closes it)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(4.0, 3.2), layout="constrained")
    x = result.values
    ax.hist(x, bins=max(5, min(30, int(np.sqrt(x.size)) + 1)), color="#9ecae1",
            edgecolor="#3182bd")
    for value, label, style in ((result.lower_limit, "LSL", "--"),
                                (result.upper_limit, "USL", "--"),
                                (result.nominal, "nominal", ":")):
        if value is not None:
            ax.axvline(value, color=_SPEC, linestyle=style, linewidth=1.5)
            ax.annotate(label, (value, 1.0), xycoords=("data", "axes fraction"),
                        ha="center", va="bottom", color=_SPEC, fontsize=8)
    ax.axvline(float(x.mean()), color="black", linewidth=1.0)
    ax.set_xlabel(axis_label(result.parameter, result.unit))
    ax.set_ylabel("runs [count]")
    _integer_ticks(ax.yaxis)
    ax.ticklabel_format(axis="x", style="plain", useOffset=False)
    ax.xaxis.set_major_locator(_ticker().MaxNLocator(nbins=4))
    return fig


def imr_png(result: SpcResult) -> bytes:
    """I chart (zones, limits, rule hits labelled), MR chart and EWMA, one above the other
    (PNG)."""
    return _png(imr_figure(result))


def imr_figure(result: SpcResult) -> Any:
    """The I-MR / EWMA charts' matplotlib figure (the caller closes it)."""
    plt = _pyplot()
    panels = 3 if result.ewma is not None else 2
    width_in = 8.0 if result.n > 30 else 6.5  # a short series needs no wide chart
    fig, axes = plt.subplots(panels, 1, figsize=(width_in, 2.1 * panels + 0.5), sharex=True,
                             layout="constrained")
    runs = np.arange(1, result.n + 1)
    lim = result.limits
    ax = axes[0]
    for k in (1, 2):
        ax.axhspan(lim.centre - k * lim.sigma, lim.centre + k * lim.sigma, color=_LIMIT,
                   alpha=0.06, linewidth=0)
    ax.plot(runs, result.values, marker="o", markersize=3, color="#444444", linewidth=0.8)
    ax.axhline(lim.centre, color=_LIMIT, linewidth=1.0)
    for level in (lim.ucl, lim.lcl):
        ax.axhline(level, color=_LIMIT, linestyle="--", linewidth=1.0)
    marked = sorted({i for hits in result.rule_hits.values() for i in hits})
    if marked:
        index = np.array(marked)
        ax.plot(index + 1, result.values[index], "o", markersize=7, markerfacecolor="none",
                markeredgecolor=_HIT, markeredgewidth=1.5, label="Nelson rule hit")
        for i, rules in _onsets(result.rule_hits).items():
            ax.annotate("rule " + ",".join(str(r) for r in rules),
                        (i + 1, result.values[i]), textcoords="offset points",
                        xytext=(-4, 9), ha="right", fontsize=7, color=_HIT)
        ax.legend(loc="upper left", fontsize=8, frameon=False)
    ax.margins(y=0.15)
    source = "frozen baseline" if result.baseline else "this series"
    ax.set_title(f"Individuals: centre and 3σ limits from {source}; shaded ±1σ, ±2σ",
                 fontsize=9, loc="left")
    ax.set_ylabel(axis_label("value", result.unit))
    ax = axes[1]
    mr = moving_ranges(result.values)
    ax.plot(runs[1:], mr, marker="o", markersize=3, color="#444444", linewidth=0.8)
    ax.axhline(lim.mr_centre, color=_LIMIT, linewidth=1.0)
    ax.axhline(lim.mr_ucl, color=_LIMIT, linestyle="--", linewidth=1.0)
    if result.mr_hits:
        mr_index = np.array(result.mr_hits)
        ax.plot(mr_index + 1, mr[mr_index - 1], "o", markersize=7, markerfacecolor="none",
                markeredgecolor=_HIT, markeredgewidth=1.5)
    ax.set_title("Moving range: centre MR̄, UCL = 3.267·MR̄", fontsize=9, loc="left")
    ax.set_ylabel(axis_label("moving range", result.unit))
    if result.ewma is not None:
        e, ax = result.ewma, axes[2]
        ax.plot(runs, e.z, marker="o", markersize=3, color="#444444", linewidth=0.8)
        ax.step(runs, e.ucl, where="mid", color=_LIMIT, linestyle="--", linewidth=1.0)
        ax.step(runs, e.lcl, where="mid", color=_LIMIT, linestyle="--", linewidth=1.0)
        ax.axhline(e.centre, color=_LIMIT, linewidth=1.0)
        if e.signals:
            s = np.array(e.signals)
            ax.plot(s + 1, e.z[s], "o", markersize=7, markerfacecolor="none",
                    markeredgecolor=_HIT, markeredgewidth=1.5)
        ax.set_title(f"EWMA λ = {e.lam:g}, L = {e.width:g} (exact limits)", fontsize=9,
                     loc="left")
        ax.set_ylabel(axis_label("EWMA", result.unit))
    axes[-1].set_xlabel("run number (time order)")
    _integer_ticks(axes[-1].xaxis)
    for ax in axes:
        ax.ticklabel_format(axis="y", style="plain", useOffset=False)
        ax.grid(alpha=0.2)
    return fig
