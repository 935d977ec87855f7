"""``gimbal-certificate.html`` and ``.pdf`` beside the gimbal certificate's JSON: the
gimbal's identity and verdict, then a section per axis (its verdict, its certificate's id,
file and SHA-256, its results as GUM asks). Each axis's full certificate (budgets, plots,
recordings) stays in its own folder, linked. Rendering never costs the record: a document
that cannot be made is named and the JSON/TXT stands."""

from __future__ import annotations

import json
import tempfile
from collections.abc import Mapping
from datetime import datetime
from html import escape
from importlib.resources import files
from pathlib import Path
from typing import Any

from hil.gimbal.certificate import cycle_time_text, rounded_results
from hil.report.html import COLOURS, STYLE

TEMPLATE = "gimbal_certificate.typ"
TITLE = "Gimbal calibration certificate"


def gimbal_view(certificate: Mapping[str, Any]) -> dict[str, Any]:
    """What a person reads, every number rounded (U to two significant digits)."""
    g = certificate["gimbal"]
    axes = []
    for axis in certificate["axes"]:
        document = (str(Path(axis["certificate"]).with_suffix(".pdf"))
                    if axis["certificate"] else None)
        rows = rounded_results(axis)
        axes.append({"axis": axis["axis"], "outcome": axis["outcome"],
                     "certificate_id": axis.get("certificate_id") or "",
                     "document": document or "", "sha256": axis.get("certificate_sha256") or "",
                     "note": axis.get("note") or "", "results": rows})
    revision = f", revision {g['revision']}" if g["revision"] else ""
    return {
        "title": TITLE, "id": certificate["certificate_id"], "outcome": certificate["outcome"],
        "passed": certificate["outcome"] in ("PASS", "MARGINAL"),
        "line": f"the worst of its {len(axes)} axes' verdicts",
        "fields": [["Gimbal serial", g["serial"]],
                   ["Part number", f"{g['part_number']}{revision}"],
                   ["Description", g["description"] or "-"],
                   ["Gimbal profile", f"{g['profile']} (SHA-256 {g['profile_sha256']})"],
                   ["Issued", certificate["issued"]],
                   ["Axes", ", ".join(f"{a['axis']} {a['outcome']}" for a in axes)],
                   ["Motion time", cycle_time_text(certificate.get("cycle_time"))]],
        "axes": axes,
    }


def render_html(view: Mapping[str, Any]) -> str:
    """The gimbal certificate as one self-contained HTML page."""
    tone = COLOURS.get(view["outcome"], COLOURS["FAIL"])
    fields = "".join(f"<tr><td>{escape(k)}</td><td>{escape(v)}</td></tr>"
                     for k, v in view["fields"])
    parts = [f"<!doctype html><html lang='en'><head><meta charset='utf-8'>"
             f"<title>{escape(view['title'])} {escape(view['id'])}</title>"
             f"<style>{STYLE}</style></head><body>",
             f"<h1>{escape(view['title'])}</h1>",
             f"<div class='banner' style='border-color:{tone};color:{tone}'>"
             f"<span class='word'>{escape(view['outcome'])}</span>"
             f"<span class='line'>{escape(view['line'])}</span></div>",
             f"<table class='fields'>{fields}</table>"]
    for axis in view["axes"]:
        colour = COLOURS.get(axis["outcome"], COLOURS["FAIL"])
        parts.append(f"<h2>Axis {escape(axis['axis'])}: "
                     f"<span style='color:{colour}'>{escape(axis['outcome'])}</span></h2>")
        if not axis["certificate_id"]:
            parts.append(f"<p>{escape(axis['note'])}</p>")
            continue
        link = escape(axis["document"])
        parts.append(f"<p>Certificate {escape(axis['certificate_id'])}: "
                     f"<a href='{link}'>{link}</a> (HTML beside it); SHA-256 of its record "
                     f"<span class='sha'>{escape(axis['sha256'])}</span></p>")
        rows = "".join(
            f"<tr><td>{escape(r['title'])}<span class='code'>{escape(r['name'])}</span></td>"
            f"<td class='n'>{escape(r['value'])}</td><td class='n'>{escape(r['u'])}</td>"
            f"<td>{escape(r['unit'])}</td><td>{escape(r['outcome'])}</td></tr>"
            for r in axis["results"])
        parts.append("<table class='results'><tr><th>result</th><th>value</th><th>U</th>"
                     f"<th>unit</th><th>outcome</th></tr>{rows}</table>")
    parts.append("<p class='small'>Values as GUM 7.2.6 asks: the expanded uncertainty U "
                 "(about 95 %) to two significant digits, the value to the same decimal "
                 "place; each axis's certificate holds the budgets, plots and recordings.</p>"
                 "</body></html>")
    return "\n".join(parts)


def render_pdf(view: Mapping[str, Any], *, certificate_json: bytes,
               issued: datetime | None = None) -> bytes:
    """The gimbal certificate typeset by typst, its JSON record attached.

    Raises
    ------
    ImportError
        The ``typst`` package is not installed.
    """
    import typst

    with tempfile.TemporaryDirectory(prefix="gimbal-hil-pdf-") as tmp:
        root = Path(tmp)
        (root / "main.typ").write_bytes(files("hil.gimbal").joinpath(TEMPLATE).read_bytes())
        (root / "view.json").write_text(json.dumps(view, ensure_ascii=False), encoding="utf-8")
        (root / "gimbal-certificate.json").write_bytes(certificate_json)
        pdf = typst.compile(str(root / "main.typ"), root=str(root), timestamp=issued)
    assert isinstance(pdf, bytes)
    return pdf


def write_documents(json_path: Path) -> list[str]:
    """HTML and PDF beside ``json_path``; what could not be written, one line each."""
    payload = json_path.read_bytes()
    certificate = json.loads(payload)
    view = gimbal_view(certificate)
    problems = []
    json_path.with_suffix(".html").write_text(render_html(view), encoding="utf-8")
    try:
        pdf = render_pdf(view, certificate_json=payload,
                         issued=datetime.fromisoformat(certificate["issued"]))
    except ImportError:
        problems.append("gimbal-certificate.pdf not written: the typst package is not "
                        "installed (pip install typst)")
    else:
        json_path.with_suffix(".pdf").write_bytes(pdf)
    return problems
