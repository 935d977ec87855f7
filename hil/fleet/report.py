"""``results report --html``: one self-contained page (figures embedded as base64 PNG)."""

from __future__ import annotations

import base64
import html
from collections.abc import Iterable, Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path

from hil.errors import InputError
from hil.fleet.baseline import Baseline
from hil.fleet.capability import IndexEstimate
from hil.fleet.charts import EwmaSettings
from hil.fleet.fmt import index_text
from hil.fleet.fpy import YieldRow, first_pass_yield
from hil.fleet.rules import DEFAULT_RULES, DESCRIPTIONS
from hil.fleet.series import RunRecord, SeriesPoint
from hil.fleet.spc import SpcResult, has_signal, spc_report

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 1100px;
       color: #222; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; } h2 { font-size: 1.2em; margin-top: 1.6em;
     border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; margin: 0.6em 0; font-size: 0.92em; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: right; white-space: nowrap; }
th { background: #f2f2f2; } td.l, th.l { text-align: left; }
td.wrap { white-space: normal; max-width: 24em; } .item { white-space: nowrap; }
.signal { color: #b00020; font-weight: 600; } .ok { color: #2e7d32; }
.note { color: #555; font-size: 0.9em; } img { max-width: 100%; }
pre { white-space: pre-wrap; font-size: 0.85em; background: #fafafa; padding: 0.5em; }
.figs { display: flex; flex-wrap: wrap; gap: 12px; align-items: flex-start; }
"""


def fleet_report_html(
    series_by_param: Mapping[str, Sequence[SeriesPoint]],
    runs: Sequence[RunRecord],
    path: str | Path,
    *,
    baselines: Mapping[str, Mapping[str, object] | Baseline] | None = None,
    rules: Iterable[int] | str = DEFAULT_RULES,
    ewma: EwmaSettings | None = None,
    title: str = "Fleet report",
    generated_at: datetime | None = None,
) -> Path:
    """Write the fleet report: Cpk table (weakest first), yield per station and day, and per
    parameter a histogram with its limits and the I-MR / EWMA charts with rule hits marked.

    Parameters
    ----------
    series_by_param : mapping
        Parameter name → its stored results.
    runs : sequence of RunRecord
        The runs, for first-pass yield.
    path : str or Path
        The HTML file to write (its folder must exist).
    baselines : mapping, optional
        Parameter → frozen baseline; those parameters are charted against it.

    Returns
    -------
    Path
        ``path``.
    """
    out = Path(path)
    if not out.parent.is_dir():
        raise InputError(f"report: folder {out.parent} does not exist")
    from hil.fleet.plots import histogram_png, imr_png

    frozen = baselines or {}
    results: list[SpcResult] = []
    problems: list[tuple[str, str]] = []
    for name, points in series_by_param.items():
        try:
            results.append(spc_report(points, parameter=name, rules=rules, ewma=ewma,
                                      limits_from="baseline" if name in frozen else "data",
                                      baseline=frozen.get(name)))
        except InputError as exc:
            problems.append((name, str(exc)))
    when = (generated_at or datetime.now(UTC)).strftime("%Y-%m-%d %H:%M %Z")
    body = [f"<h1>{html.escape(title)}</h1>",
            f"<p class='note'>Generated {html.escape(when)}. {len(results)} parameters, "
            f"{len(runs)} runs. Reference (golden) units and aborted runs are left out. "
            "Capability intervals (95 %): Cpk/Ppk Bissell (1990) in the table, Cp/Pp χ² in "
            "each result's section; within σ = MR̄/1.128. Methods: docs/fleet.md.</p>",
            "<h2>Capability, weakest first</h2>",
            _cpk_table([r for r in results if r.charted])]
    flat = [r for r in results if not r.charted]
    if flat:  # σ = 0: said in words, not charted (a flat line and one bar show nothing)
        body.append("<h2>Results with no spread</h2><ul>" + "".join(
            f"<li id='{html.escape(r.parameter)}'>{html.escape(r.parameter)}: "
            f"{html.escape(r.no_spread)}.</li>" for r in flat) + "</ul>")
    if problems:
        body.append("<h2>Results not analysed</h2><ul>" + "".join(
            f"<li>{html.escape(name)}: {html.escape(message)}</li>"
            for name, message in problems) + "</ul>")
    body += ["<h2>First-pass yield per station</h2>",
             _yield_table(first_pass_yield(runs, by="station"), "station"),
             "<h2>First-pass yield per day</h2>",
             _yield_table(first_pass_yield(runs, by="day"), "day")]
    for result in sorted((r for r in results if r.charted), key=_weakness):
        body.append(f"<h2 id='{html.escape(result.parameter)}'>"
                    f"{html.escape(result.parameter)} ({html.escape(result.unit)})</h2>")
        body.append(f"<pre>{html.escape(result.table())}</pre>")
        body.append("<div class='figs'>" + _img(histogram_png(result), "histogram")
                    + _img(imr_png(result), "I-MR and EWMA charts") + "</div>")
    page = ("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            f"<title>{html.escape(title)}</title><style>{_STYLE}</style></head><body>"
            + "\n".join(body) + "</body></html>\n")
    out.write_text(page, encoding="utf-8")
    return out


def _weakness(result: SpcResult) -> tuple[int, float]:
    cpk = result.capability.cpk.value if result.capability else None
    return (1, 0.0) if cpk is None else (0, cpk)


def _cpk_table(results: Sequence[SpcResult]) -> str:
    rows = ["<table><tr><th class='l'>parameter</th><th>n</th><th>Cpk [95 % CI]</th>"
            "<th>Ppk [95 % CI]</th><th>Cp</th><th>Pp</th><th class='l'>signals</th></tr>"]
    for r in sorted(results, key=_weakness):
        c = r.capability
        fired = [f"rule {k}: {len(v)}" for k, v in r.rule_hits.items() if v]
        if r.mr_hits:
            fired.append(f"MR: {len(r.mr_hits)} (not gated)")
        if r.ewma is not None and r.ewma.signals:
            fired.append(f"EWMA: {len(r.ewma.signals)}")
        items = "; ".join(f"<span class='item'>{html.escape(f)}</span>" for f in fired)
        signal = (f"<span class='signal'>{items}</span>"
                  if has_signal(r) else "<span class='ok'>none</span>")
        cells = ("".join(f"<td>{index_text(e)}</td>" for e in (c.cpk, c.ppk))
                 + "".join(f"<td>{value_text(e)}</td>" for e in (c.cp, c.pp))
                 if c else f"<td colspan='4' class='l wrap'>{html.escape(r.capability_note)}</td>")
        rows.append(f"<tr><td class='l'><a href='#{html.escape(r.parameter)}'>"
                    f"{html.escape(r.parameter)}</a></td><td>{r.n}</td>" + cells
                    + f"<td class='l wrap'>{signal}</td></tr>")
    rows.append("</table>")
    legend = "; ".join(f"{k}: {v}" for k, v in DESCRIPTIONS.items())
    return "".join(rows) + f"<p class='note'>Nelson rules — {html.escape(legend)}.</p>"


def value_text(estimate: IndexEstimate) -> str:
    """An index without its interval (``1.41``), ``—`` when undefined."""
    return "—" if estimate.value is None else f"{estimate.value:.2f}"


def _yield_table(rows: Sequence[YieldRow], by: str) -> str:
    if not rows:
        return "<p class='note'>No completed runs.</p>"
    out = [f"<table><tr><th class='l'>{by}</th><th>units</th><th>PASS</th><th>MARGINAL</th>"
           "<th>FAIL</th><th>first-pass yield</th></tr>"]
    for row in rows:
        key = row.station if by == "station" else (row.day.isoformat() if row.day else "")
        out.append(f"<tr><td class='l'>{html.escape(key or '')}</td><td>{row.units}</td>"
                   f"<td>{row.passed}</td><td>{row.marginal}</td><td>{row.failed}</td>"
                   f"<td>{100 * row.first_pass_yield:.1f} %</td></tr>")
    out.append("</table>")
    return "".join(out)


def _img(png: bytes, alt: str) -> str:
    data = base64.b64encode(png).decode("ascii")
    return f"<img alt='{html.escape(alt)}' src='data:image/png;base64,{data}'>"
