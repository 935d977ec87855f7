"""Figure plumbing shared by the protocol plots: a styled matplotlib figure (no pyplot
state, so any backend and thread will do), decimation and export to PNG or SVG."""

from __future__ import annotations

import io
from contextlib import AbstractContextManager
from typing import Any, cast

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

WIDTH_IN = 7.4
HEIGHT_IN = 2.9
#: Most points drawn per line: more are invisible at print size and bloat the SVG.
MAX_POINTS = 2500
STYLE: dict[str, Any] = {
    "font.size": 8.0,
    "axes.titlesize": 8.5,
    "axes.labelsize": 8.0,
    "legend.fontsize": 7.0,
    "xtick.labelsize": 7.0,
    "ytick.labelsize": 7.0,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "lines.linewidth": 1.0,
    "svg.fonttype": "path",
    "svg.hashsalt": "gimbal-hil",
}
MEASURED = "#7f7f7f"
MODEL = "#d62728"
COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#17becf")


def styled() -> AbstractContextManager[None]:
    """The plots' matplotlib settings; draw and export inside it."""
    from matplotlib import rc_context

    return rc_context(cast(Any, STYLE))


def new_figure(columns: int = 2, rows: int = 1, *, height_in: float = HEIGHT_IN) -> Figure:
    """A figure of ``rows`` × ``columns`` axes, the width of a certificate's text column.

    Parameters
    ----------
    columns, rows : int
        The grid of axes.
    height_in : float
        Height (inches).

    Returns
    -------
    Figure
        With its axes in ``fig.axes``, row by row.
    """
    fig = Figure(figsize=(WIDTH_IN, height_in), layout="constrained")
    fig.subplots(rows, columns, squeeze=False)
    return fig


def thin(*arrays: NDArray[Any], limit: int = MAX_POINTS) -> tuple[NDArray[Any], ...]:
    """Every k-th sample of each array, so that at most ``limit`` remain.

    Parameters
    ----------
    *arrays : ndarray
        Arrays of the same length.
    limit : int
        Most samples kept.

    Returns
    -------
    tuple of ndarray
        The arrays thinned alike.
    """
    step = max(1, int(np.ceil(len(arrays[0]) / limit)))
    return tuple(np.asarray(a)[::step] for a in arrays)


def png_bytes(fig: Figure, *, dpi: float = 110.0) -> bytes:
    """The figure as PNG.

    Parameters
    ----------
    fig : Figure
        The figure.
    dpi : float
        Resolution (dots per inch).

    Returns
    -------
    bytes
    """
    buffer = io.BytesIO()
    with styled():
        fig.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()


def svg_bytes(fig: Figure) -> bytes:
    """The figure as self-contained SVG (text as paths, no fonts needed).

    Parameters
    ----------
    fig : Figure
        The figure.

    Returns
    -------
    bytes
    """
    buffer = io.BytesIO()
    with styled():
        fig.savefig(buffer, format="svg", metadata={"Date": None})
    return buffer.getvalue()
