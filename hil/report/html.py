"""The certificate as one self-contained HTML file (inline CSS, plots as base64 PNG)."""

from __future__ import annotations

import base64
from collections.abc import Mapping
from html import escape
from typing import Any

COLOURS = {"PASS": "#1a7f37", "MARGINAL": "#9a6700", "FAIL": "#cf222e", "ERROR": "#cf222e"}
STYLE = """
body{font-family:system-ui,-apple-system,"Segoe UI",sans-serif;max-width:1000px;margin:2em auto;
color:#1f2328;font-size:14px;line-height:1.4;padding:0 1em}
h1{font-size:1.5em}h3{font-size:1.05em;margin:.2em 0}
h2{font-size:1.2em;margin-top:1.6em;border-bottom:1px solid #d0d7de}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #d0d7de;padding:3px 7px;
vertical-align:top}th{background:#f6f8fa;text-align:left}td.n{text-align:right;
font-variant-numeric:tabular-nums}table.fields td{border:none;padding:2px 8px}
table.fields td:first-child{font-weight:600;white-space:nowrap}
.banner{border:3px solid;border-radius:6px;padding:12px 16px;margin:1em 0}
.banner .word{font-size:2.6em;font-weight:800;letter-spacing:.04em;margin-right:.4em}
.banner .line{font-size:1.2em;font-weight:600}
.sha{font-family:ui-monospace,monospace;font-size:11px}figure{margin:1em 0}
figure img{max-width:100%}figcaption{font-weight:600}.small{font-size:12px;color:#57606a}
.code{font-family:ui-monospace,monospace;font-size:10px;color:#57606a;margin-left:.5em}
.desc{font-size:12px;color:#57606a}tr.group td{background:#f6f8fa;font-weight:600}
.authorised{margin-top:.3em;font-weight:600}
table.results td+td{white-space:nowrap}
.watermark{position:fixed;top:40%;left:0;right:0;text-align:center;font-size:120px;
font-weight:900;opacity:.08;transform:rotate(-30deg);pointer-events:none}
"""


def render_html(view: Mapping[str, Any], *, plots_png: Mapping[str, bytes]) -> str:
    """The certificate page.

    Parameters
    ----------
    view : mapping
        :func:`hil.report.view.certificate_view`, each protocol's ``plot`` naming its
        entry in ``plots_png`` (or ``None``).
    plots_png : mapping
        File name → PNG bytes of each plot.

    Returns
    -------
    str
        The HTML document.
    """
    colour = COLOURS.get(view["outcome"], COLOURS["ERROR"])
    word, line = escape(view["banner"]["word"]), escape(view["banner"]["line"])
    out = [
        "<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{escape(view['title'])}: {escape(view['id'])} ({word})</title>",
        f"<style>{STYLE}</style></head><body>",
    ]
    if not view["passed"]:
        out.append(f'<div class="watermark" style="color:{colour}">{word}</div>')
    authorised = (f"Authorised by {escape(view['authorised_by'])}" if view["authorised"]
                  else "NOT AUTHORISED: no one has authorised this certificate")
    out += [
        f"<h1>{escape(view['title'])}</h1>",
        f'<div class="banner" style="border-color:{colour};background:{colour}14">'
        f'<span class="word" style="color:{colour}">{word}</span>'
        f'<span class="line" style="color:{colour}">{line}</span>'
        f"<div>{escape(view['conformity'])}</div>"
        f'<div class="authorised">{authorised}</div></div>',
        '<table class="fields">',
        *(f"<tr><td>{escape(k)}</td><td>{escape(v)}</td></tr>" for k, v in view["fields"]),
        "</table>",
        "<h2>Results</h2>",
        "<p>Values as GUM 7.2.6 asks: U (coverage factor k, about 95 %) to two significant "
        "digits, the value to the same decimal place; certificate.json keeps full "
        "precision.</p>",
        _results(view["groups"]),
        *(["<h3>Not measured</h3>", _table(
            ("result", "protocol", "", "why"),
            [[m["parameter"], m["protocol"], m["required"], m["reason"]]
             for m in view["not_measured"]], numeric=set())] if view["not_measured"] else []),
        f"<p><b>Decision rule.</b> {escape(view['decision_rule'])}</p>",
        f'<p><b>Conformity statement.</b> <b style="color:{colour}">{word}:</b> '
        f"{escape(view['conformity'])}</p>",
        "<h2>Plots</h2>",
    ]
    for p in view["protocols"]:
        if p.get("plot") and p["plot"] in plots_png:
            data = base64.b64encode(plots_png[p["plot"]]).decode("ascii")
            out.append(f"<figure><h3>{escape(p['title'])}</h3>"
                       f"<figcaption>{escape(p['name'])} ({escape(p['outcome'])}): "
                       f"{escape(p.get('caption', ''))}</figcaption>"
                       f'<img alt="{escape(p["name"])} plot" src="data:image/png;base64,{data}">'
                       "</figure>")
    out.append("<h2>Uncertainty budgets</h2><p>Standard uncertainties (k = 1): each input's "
               "u(x), sensitivity c, contribution |c|·u(x) and its share of u².</p>")
    for b in view["budgets"]:
        out.append(f"<p><b>{escape(b['title'])}</b>{_code(b['parameter'])} "
                   f"{escape(b['summary'])}<br><span class=desc>{escape(b['description'])}"
                   "</span></p>")
        out.append(_table(("component", "type", "u(x)", "c", "contribution", "share"),
                          [[line["component"], line["type"], line["u"], line["c"],
                            line["contribution"], line["share"]] for line in b["lines"]],
                          numeric={2, 3, 4, 5}))
        if b["validated"]:
            out.append(f"<p class=desc>{escape(b['validated'])}</p>")
    out.append("<h2>Protocols</h2>")
    out.append(_table(("protocol", "outcome", "motion", "messages"),
                      [[f"{p['title']} ({p['name']})", p["outcome"], p["motion"],
                        "\n".join(p["messages"])] for p in view["protocols"]], numeric={2}))
    out.append("<h2>Raw data and derived files (SHA-256)</h2><table>")
    out += [f'<tr><td>{escape(f["file"])}</td><td class="sha">{escape(f["sha256"])}</td></tr>'
            for f in [*view["raw_data"], *view["artifacts"]]]
    out.append(f"</table><p class=\"small\">Certificate {escape(view['id'])}</p></body></html>")
    return "\n".join(out) + "\n"


def _code(name: str) -> str:
    """A result's code name, small beside its title."""
    return f'<span class="code">{escape(name)}</span>'


def _results(groups: list[dict[str, Any]]) -> str:
    """The results table, a row per protocol ahead of its results: title, code name and
    description in the first column."""
    header = ("result", "value", "U", "k", "unit", "limits", "outcome")
    rows = ['<table class="results"><tr>' + "".join(f"<th>{h}</th>" for h in header)
            + "</tr>"]
    for group in groups:
        rows.append(f'<tr class="group"><td colspan="7">{escape(group["title"])}'
                    f'{_code(group["name"])}</td></tr>')
        for r in group["results"]:
            first = (f"{escape(r['title'])}{_code(r['parameter'])}"
                     f"<br><span class=desc>{escape(r['description'])}</span>")
            cells = "".join(_cell(r[key], key in ("value", "U", "k"))
                            for key in ("value", "U", "k", "unit", "limits", "outcome"))
            rows.append(f"<tr><td>{first}</td>{cells}</tr>")
    return "".join(rows) + "</table>"


def _table(header: tuple[str, ...], rows: list[list[str]], *, numeric: set[int]) -> str:
    head = "".join(f"<th>{escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(_cell(cell, i in numeric) for i, cell in enumerate(row))
                   + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _cell(text: str, numeric: bool) -> str:
    if text in COLOURS:  # an outcome: coloured as the banner
        return f'<td style="color:{COLOURS[text]};font-weight:700">{text}</td>'
    body = escape(text).replace("\n", "<br>")
    return f"<td class=n>{body}</td>" if numeric else f"<td>{body}</td>"
