"""Fleet statistics over stored calibration results: pure numerics (capability indices with
confidence intervals, individuals / moving-range charts, Nelson rules, EWMA, first-pass
yield) and their rendering (tables, JSON, a self-contained HTML report).

Imports numpy, scipy, ``hil.gum`` and ``hil.errors`` only (matplotlib for the report, pyarrow
for parquet, each when asked); never the results store: callers hand in any sequence of
objects with the attributes of :class:`hil.fleet.series.SeriesPoint`. Formulas and sources:
``docs/fleet.md``.
"""
