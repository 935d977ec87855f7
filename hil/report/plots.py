"""One figure per protocol that ran, made from its raw recordings and details with the
project's own identification functions (:mod:`hil.identify`, :mod:`hil.closed_loop`), and
its caption."""

from __future__ import annotations

import logging
from collections.abc import Callable

from matplotlib.figure import Figure

from hil.report import plots_closed_loop, plots_frequency, plots_motion
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
    "cross_coupling": plots_motion.cross_coupling,
    "velocity_loop_frf": plots_closed_loop.velocity_loop_frf,
    "velocity_step": plots_closed_loop.velocity_step,
    "tracking": plots_closed_loop.tracking,
    "standstill": plots_closed_loop.standstill,
    "cogging_compensation": plots_closed_loop.cogging_compensation,
}
#: What each plot shows, under it on the certificate (``hil.report.documents``).
CAPTIONS = {
    "inertia_friction": "the J/B/T_c sine fit against the recorded torque, and the friction "
                        "it leaves",
    "stribeck": "steady friction per staircase speed and the fitted Stribeck curve",
    "gravity_cable": "the sweep's hysteresis loop, and the load per position with its fit",
    "cogging": "order spectrum against angle, and the ripple map against the compensation table",
    "current_loop": "lag phase per frequency and the sampled-data model with the fitted τ",
    "resonance": "frequency response (Bode) and the two-mass fit",
    "torque_constant": "shaft torque against current at each locked angle, and its linearity",
    "inertia_elevation": "azimuth inertia per elevation, the cos² + sin(2el) fit and its extremes",
    "cross_coupling": "the torque the azimuth needs while the elevation swings (swinging "
                      "pass less standing pass) and the fitted coupling, each direction",
    "velocity_loop_frf": "closed loop and sensitivity with the −3 dB bandwidth, and the loop "
                         "gain with its gain and phase margins (Bode)",
    "velocity_step": "every step normalised to its size, small and large, with the 10–90 % "
                     "rise, the overshoot and the 2 % settling",
    "tracking": "following error over the standard move without and with the friction "
                "feedforward",
    "standstill": "held position and reported torque about each block's line, one block "
                  "per hold position, with each block's RMS (jitter, torque ripple)",
    "cogging_compensation": "position ripple against angle with the compensation table "
                            "cleared and loaded, and its amplitude per order",
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
