"""The certificate as PDF, typeset by typst (the ``typst`` wheel: no system packages)."""

from __future__ import annotations

import json
import tempfile
from collections.abc import Mapping
from datetime import datetime
from importlib.resources import files
from pathlib import Path
from typing import Any

TEMPLATE = "certificate.typ"


def render_pdf(view: Mapping[str, Any], *, certificate_json: bytes, plots: Mapping[str, bytes],
               issued: datetime | None = None) -> bytes:
    """Typeset the certificate.

    Parameters
    ----------
    view : mapping
        :func:`hil.report.view.certificate_view`, each protocol's ``plot`` naming its
        entry in ``plots`` (or ``None``).
    certificate_json : bytes
        ``certificate.json`` as written: attached to the PDF unchanged, the record.
    plots : mapping
        File name → image bytes (PNG or SVG) of each plot.
    issued : datetime or None
        The PDF's creation date (the certificate's issue time: reproducible output).

    Returns
    -------
    bytes
        The PDF.

    Raises
    ------
    ImportError
        The ``typst`` package is not installed.
    typst.TypstError
        The template did not compile.
    """
    import typst

    sources: dict[str, bytes] = {
        "main.typ": files("hil.report").joinpath(TEMPLATE).read_bytes(),
        "view.json": json.dumps(view, ensure_ascii=False).encode("utf-8"),
        "certificate.json": certificate_json,
        **plots,
    }
    # typst reads images from files (its in-memory sources must be UTF-8 text)
    with tempfile.TemporaryDirectory(prefix="gimbal-hil-pdf-") as tmp:
        root = Path(tmp)
        for name, payload in sources.items():
            (root / name).write_bytes(payload)
        pdf = typst.compile(str(root / "main.typ"), root=str(root), timestamp=issued)
    assert isinstance(pdf, bytes)
    return pdf
