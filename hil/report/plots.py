"""One figure per protocol that ran, made from its raw recordings and details with the
project's own identification functions (:mod:`hil.identify`)."""

from __future__ import annotations

import logging
from collections.abc import Callable

from matplotlib.figure import Figure

from hil.report import plots_frequency, plots_motion
from hil.report.data import ProtocolData
from hil.report.figures import png_bytes, styled, svg_bytes

log = logging.getLogger(__name__)

PLOTTERS: dict[str, Callable[[ProtocolData], Figure | None]] = {
    "current_loop": plots_frequency.current_loop,
    "gravity_cable": plots_motion.gravity_cable,
    "inertia_friction": plots_motion.inertia_friction,
    "stribeck": plots_motion.stribeck,
    "cogging": plots_frequency.cogging,
    "resonance": plots_frequency.resonance,
    "torque_constant": plots_motion.torque_constant,
    "inertia_elevation": plots_motion.inertia_elevation,
}


def protocol_figure(data: ProtocolData) -> Figure | None:
    """The protocol's figure, or ``None`` when it has no plot or kept too little to draw.

    Parameters
    ----------
    data : ProtocolData
        The protocol's details, results and raw recordings.

    Returns
    -------
    Figure or None
    """
    plotter = PLOTTERS.get(data.name)
    if plotter is None:
        return None
    with styled():
        return plotter(data)


def protocol_images(data: ProtocolData, *, svg: bool = False) -> bytes | None:
    """The protocol's figure as PNG (or SVG) bytes; ``None`` as :func:`protocol_figure`."""
    fig = protocol_figure(data)
    if fig is None:
        return None
    return svg_bytes(fig) if svg else png_bytes(fig)
