"""A comparison as a person reads it (GUM rounding) and as JSON (full precision)."""

from __future__ import annotations

import math
from typing import Any

from hil.compare.budget import Sharing
from hil.compare.certificates import Result
from hil.compare.verdict import Comparison, Row, Verdict
from hil.gum import format_result, rounded_pair

VERDICT_SEVERITY = (Verdict.WORSE, Verdict.CHANGED, Verdict.MISSING, Verdict.INCONCLUSIVE,
                    Verdict.NEW, Verdict.BETTER, Verdict.SAME)
HEADER = ("unit", "result", "baseline ± U", "candidate ± U", "Δ ± U(Δ)", "Δ %", "E", "p",
          "p Holm", "verdict")


def table_rows(comparison: Comparison) -> list[tuple[str, ...]]:
    """The table's cells, rounded for reading (U two significant digits, GUM 7.2.6)."""
    return [_cells(row) for row in comparison.rows]


def render_text(comparison: Comparison) -> str:
    """The console report: table, warnings, the budget of each difference, the rules."""
    cells = [HEADER, *table_rows(comparison)]
    widths = [max(len(line[i]) for line in cells) for i in range(len(HEADER))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(line, widths, strict=True)).rstrip()
             for line in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    remarks = [*(f"warning: {w}" for w in comparison.warnings),
               *(f"note: {n}" for n in comparison.notes)]
    lines += ["", *remarks] if remarks else []
    lines += ["", "Budget of the difference (contributions in the result's unit; shared lines "
              "enter as the difference of their two contributions):"]
    lines += [f"  {_budget_line(row)}" for row in comparison.rows if row.budget is not None]
    lines += ["", *comparison.rules]
    # the verdict last: what a person (or a log's tail) reads first
    lines += ["", f"VERDICT: {overall_verdict(comparison)}. {summary(comparison)}"]
    return "\n".join(lines) + "\n"


def render_markdown(comparison: Comparison) -> str:
    """A table for a pull-request comment, with the rules in a collapsed block."""
    out = [f"**gimbal-hil compare**: {summary(comparison)}", ""]
    out += [f"> ⚠ {w}" for w in comparison.warnings]
    out += ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    for cells in table_rows(comparison):
        out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    out += ["", "<details><summary>Budget of the difference and the rules</summary>", ""]
    out += [f"- {_budget_line(row)}" for row in comparison.rows if row.budget is not None]
    out += ["", *(f"{rule}\n" for rule in comparison.rules), "</details>", ""]
    return "\n".join(out)


def overall_verdict(comparison: Comparison) -> str:
    """The comparison in one word: its most serious result verdict (WORSE before CHANGED,
    MISSING, INCONCLUSIVE, NEW, BETTER, SAME)."""
    found = {row.verdict for row in comparison.rows}
    return next((v.value for v in VERDICT_SEVERITY if v in found), Verdict.SAME.value)


def summary(comparison: Comparison) -> str:
    """One line: what was compared and what is flagged."""
    counts: dict[str, int] = {}
    for row in comparison.rows:
        counts[row.verdict.value] = counts.get(row.verdict.value, 0) + 1
    flagged = ", ".join(f"{r.parameter} {r.verdict.value}" for r in comparison.flagged())
    tally = ", ".join(f"{n} {v}" for v, n in sorted(counts.items()))
    return (f"{len(comparison.rows)} results of {len(comparison.pairs)} unit(s), Holm at "
            f"alpha {comparison.alpha:g}: {tally}. "
            + (f"Flagged: {flagged} (exit 1)." if flagged else "Nothing flagged (exit 0)."))


def as_json(comparison: Comparison) -> dict[str, Any]:
    """Everything, full precision (``null`` for what does not apply)."""
    return {
        "schema": "gimbal-hil/compare/v1",
        "alpha": comparison.alpha,
        "exit_code": comparison.exit_code,
        "pairs": [{"baseline": b, "candidate": c} for b, c in comparison.pairs],
        "warnings": list(comparison.warnings),
        "notes": list(comparison.notes),
        "rules": list(comparison.rules),
        "results": [_row_json(row) for row in comparison.rows],
    }


def _cells(row: Row) -> tuple[str, ...]:
    b, c = _side(row.baseline), _side(row.candidate)
    if row.difference is None or row.expanded_uncertainty is None:
        return (row.serial, row.parameter, b, c, "", "", "", "", "", row.verdict.value)
    diff = format_result(row.difference, row.expanded_uncertainty, row.unit)
    pct = ""
    if row.difference_pct is not None and row.baseline is not None:
        pct = rounded_pair(row.difference_pct,
                           100 * row.expanded_uncertainty / abs(row.baseline.value))[0]
    return (row.serial, row.parameter, b, c, diff, pct, _number(row.normalised),
            _p(row.p_value), _p(row.p_holm), row.verdict.value)


def _side(result: Result | None) -> str:
    if result is None:
        return "—"
    return format_result(result.value, result.expanded_uncertainty, result.unit)


def _number(x: float | None) -> str:
    if x is None:
        return ""
    return f"{x:+.2f}" if math.isfinite(x) else f"{x}"


def _p(p: float | None) -> str:
    if p is None:
        return ""
    return "<1e-6" if p < 1e-6 else f"{p:.2g}"


def _budget_line(row: Row) -> str:
    assert row.budget is not None
    parts = []
    for line in row.budget.lines:
        if line.sharing is Sharing.SHARED:
            parts.append(f"{line.source}: {abs(line.baseline_contribution):.2g} → "
                         f"{line.contribution:.2g} (shared: {line.reason})")
        else:
            parts.append(f"{line.source}: {line.contribution:.2g} "
                         f"(independent: {line.reason})")
    dof = f"{row.budget.dof:.0f}" if math.isfinite(row.budget.dof) else "∞"
    return (f"{row.serial} {row.parameter}: u(Δ) {row.budget.standard_uncertainty:.2g} "
            f"{row.unit}, ν {dof}; " + "; ".join(parts))


def _row_json(row: Row) -> dict[str, Any]:
    def side(r: Result | None) -> dict[str, Any] | None:
        if r is None:
            return None
        return {"value": r.value, "standard_uncertainty": r.standard_uncertainty,
                "expanded_uncertainty": r.expanded_uncertainty, "outcome": r.outcome}

    budget = None
    if row.budget is not None:
        budget = {
            "standard_uncertainty": row.budget.standard_uncertainty,
            "degrees_of_freedom": row.budget.dof if math.isfinite(row.budget.dof) else None,
            "lines": [{"component": d.source, "sharing": d.sharing.value, "reason": d.reason,
                       "baseline_contribution": d.baseline_contribution,
                       "candidate_contribution": d.candidate_contribution,
                       "contribution": d.contribution} for d in row.budget.lines],
        }
    return {
        "serial": row.serial, "parameter": row.parameter, "unit": row.unit,
        "direction": row.direction, "baseline": side(row.baseline),
        "candidate": side(row.candidate), "difference": row.difference,
        "difference_pct": row.difference_pct,
        "difference_expanded_uncertainty": row.expanded_uncertainty,
        "normalised_difference": (row.normalised if row.normalised is not None
                                  and math.isfinite(row.normalised) else None),
        "p_value": row.p_value, "p_holm": row.p_holm, "verdict": row.verdict.value,
        "budget_of_difference": budget,
    }
