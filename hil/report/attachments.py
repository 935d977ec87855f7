"""Allure attachments of one protocol: its plot (PNG) and its raw recordings (CSV).

Only called when allure-pytest is active; ``allure`` is imported here, never at import time.
"""

from __future__ import annotations

import gzip
import logging

from hil.calibration import CalibrationRun
from hil.report.data import from_run
from hil.report.figures import png_bytes, styled
from hil.report.plots import protocol_figure

log = logging.getLogger(__name__)


def attach_protocol(run: CalibrationRun, name: str) -> None:
    """Attach protocol ``name``'s plot and raw recordings to the current Allure test.

    Parameters
    ----------
    run : CalibrationRun
        The calibration in progress (the protocol's details, results and recordings).
    name : str
        The protocol.
    """
    import allure

    data = from_run(run, name)
    try:
        with styled():
            fig = protocol_figure(data)
            png = None if fig is None else png_bytes(fig)
    except Exception as exc:  # boundary: a plot fault must not fail the protocol's test
        log.warning("plot of %s not drawn for Allure: %s: %s", name, type(exc).__name__, exc)
        png = None
    if png is not None:
        allure.attach(png, name=f"{name}.png", attachment_type=allure.attachment_type.PNG)
    for excitation, path in data.recordings.items():
        payload = path.read_bytes()
        if path.suffix == ".gz":
            payload = gzip.decompress(payload)
        allure.attach(payload, name=f"{name}__{excitation}.csv",
                      attachment_type=allure.attachment_type.CSV)
