"""The pure functions behind ``gimbal-hil results spc / trend / export / report``: each takes
stored results (any objects with :class:`hil.fleet.series.SeriesPoint`'s attributes) and
returns a result with ``table()`` and ``to_json()`` or writes a file. ``has_signal`` is the
exit status of ``spc``: 1 on a signal, so a line can gate on it."""

from __future__ import annotations

from hil.fleet.baseline import Baseline, freeze_baseline
from hil.fleet.charts import EwmaSettings
from hil.fleet.export import export_rows
from hil.fleet.fpy import YieldResult, YieldRow, first_pass_yield, yield_table
from hil.fleet.report import fleet_report_html
from hil.fleet.spc import SpcResult, has_signal, spc_report
from hil.fleet.trend import TrendResult, trend_table

__all__ = [
    "Baseline", "EwmaSettings", "SpcResult", "TrendResult", "YieldResult", "YieldRow",
    "export_rows", "first_pass_yield", "fleet_report_html", "freeze_baseline", "has_signal",
    "spc_report", "trend_table", "yield_table",
]
