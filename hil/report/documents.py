"""``certificate.html`` and ``certificate.pdf`` beside ``certificate.json``, made from it
and the run's raw recordings. Rendering never costs the record: whatever fails is named
and the JSON/TXT certificate stands as written."""

from __future__ import annotations

import json
import logging
import pickle
from datetime import datetime
from pathlib import Path
from typing import Any

from hil.certificate.integrity import verify_certificate
from hil.certificate.model import Certificate, read_certificate
from hil.errors import InputError
from hil.parallel import forked_bytes
from hil.recording import write_atomic
from hil.report.data import ProtocolData, from_certificate
from hil.report.figures import png_bytes, styled
from hil.report.html import render_html
from hil.report.pdf import render_pdf
from hil.report.plots import CAPTIONS, protocol_figure
from hil.report.view import certificate_view

log = logging.getLogger(__name__)

PLOT_DPI = 160.0  # sharp in print at the text width (7.4 in), small enough for e-mail


def certificate_file(target: Path) -> Path:
    """The ``certificate.json`` that ``target`` names (the file, or a unit's directory).

    Parameters
    ----------
    target : Path
        A ``certificate.json`` or the directory holding one.

    Returns
    -------
    Path
        The certificate file, checked to be a gimbal-hil certificate and verified
        (:mod:`hil.certificate.integrity`: one written before digests with a warning).

    Raises
    ------
    InputError
        No such file, not JSON, not a gimbal-hil certificate, or not verified: its content
        edited, a recording changed or missing, an outcome its results do not give.
    """
    path = target / "certificate.json" if target.is_dir() else target
    if not path.is_file():
        raise InputError("no certificate.json here", source=str(target))
    read_certificate(path)  # a gimbal-hil certificate, every key as its schema states
    verification = verify_certificate(path)  # the plots are drawn from its recordings
    if verification.refusals:
        raise InputError(verification.refusal(), source=str(path))
    for warning in verification.warnings:
        log.warning("%s: %s", path, warning)
    return path


def write_documents(certificate_path: Path) -> list[str]:
    """Write ``certificate.html`` and ``certificate.pdf`` next to ``certificate_path``.

    Parameters
    ----------
    certificate_path : Path
        The written ``certificate.json`` (its raw recordings beside it).

    Returns
    -------
    list of str
        One line per thing that could not be made (a plot, the HTML, the PDF); empty when
        everything was written.
    """
    unit_dir = certificate_path.parent
    record = certificate_path.read_bytes()
    cert = Certificate.from_json(json.loads(record), source=str(certificate_path))
    problems: list[str] = []
    view = certificate_view(cert)
    pngs = _plots(cert, unit_dir, view, problems)
    try:
        html = render_html(view, plots_png=pngs)
        write_atomic(unit_dir / "certificate.html", html.encode("utf-8"))
    except Exception as exc:  # boundary: the JSON record must survive any rendering fault
        problems.append(f"certificate.html not written: {type(exc).__name__}: {exc}")
    try:
        issued = datetime.fromisoformat(cert.dates.issued)
        pdf = render_pdf(view, certificate_json=record, plots=pngs, issued=issued)
        write_atomic(unit_dir / "certificate.pdf", pdf)
    except ImportError:
        problems.append("certificate.pdf not written: the typst package is not installed "
                        "(pip install typst)")
    except Exception as exc:  # boundary, as above
        problems.append(f"certificate.pdf not written: {type(exc).__name__}: {exc}")
    for problem in problems:
        log.warning("%s: %s", unit_dir, problem)
    return problems


def _plots(cert: Certificate, unit_dir: Path, view: dict[str, Any], problems: list[str]
           ) -> dict[str, bytes]:
    """Each protocol's plot as PNG (one raster for both documents: an SVG of thousands of
    points costs more to make than the rest of the document); sets ``plot`` and
    ``caption`` in ``view``. Drawing is most of the documents' time (about 0.4 s a plot), so
    the second half is drawn on another core where a child can be forked
    (:func:`hil.parallel.forked_bytes`)."""
    by_name = {p["name"]: p for p in view["protocols"]}
    for entry in by_name.values():
        entry["plot"], entry["caption"] = None, CAPTIONS.get(entry["name"], "")
    data = from_certificate(cert, unit_dir)
    half = (len(data) + 1) // 2
    first, second = forked_bytes(lambda: pickle.dumps(_drawn(data[half:])),
                                 lambda: _drawn(data[:half]))
    drawn = {**first, **(_drawn(data[half:]) if second is None else pickle.loads(second))}
    pngs: dict[str, bytes] = {}
    for item in data:  # in the certificate's order
        outcome = drawn.get(item.name)
        if isinstance(outcome, str):
            problems.append(outcome)
        elif outcome is not None:
            pngs[f"{item.name}.png"] = outcome
            by_name[item.name]["plot"] = f"{item.name}.png"
    return pngs


def _drawn(data: list[ProtocolData]) -> dict[str, bytes | str]:
    """Each protocol's PNG, or the line saying why it could not be drawn; none for a
    protocol without a plot."""
    out: dict[str, bytes | str] = {}
    for item in data:
        try:
            with styled():
                fig = protocol_figure(item)
                if fig is not None:
                    out[item.name] = png_bytes(fig, dpi=PLOT_DPI)
        except Exception as exc:  # boundary: one bad plot must not cost the document
            out[item.name] = f"plot of {item.name} not drawn: {type(exc).__name__}: {exc}"
    return out
