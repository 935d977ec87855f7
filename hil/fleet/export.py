"""``export --format csv|parquet``: the stored results as rows for other tools."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path

from hil.errors import InputError
from hil.fleet.series import SERIES_FIELDS, SeriesPoint


def export_rows(points: Sequence[SeriesPoint], *, format: str = "csv",
                path: str | Path) -> Path:
    """Write every point as one row (columns: :data:`hil.fleet.series.SERIES_FIELDS`).

    Parameters
    ----------
    points : sequence of SeriesPoint
        Written in the given order, reference units included (the column says which).
    format : {"csv", "parquet"}
        CSV: UTF-8, header row, ISO 8601 times, empty cell for a missing limit, full float
        precision (``repr``). Parquet: typed columns (timestamp, float64, bool), via pyarrow.
    path : str or Path
        The file to write; its folder must exist.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    InputError
        Unknown format, pyarrow missing for parquet, or the folder does not exist.
    """
    out = Path(path)
    if not out.parent.is_dir():
        raise InputError(f"export: folder {out.parent} does not exist")
    if format == "csv":
        with out.open("w", newline="", encoding="utf-8") as handle:
            writer = csv.writer(handle)
            writer.writerow(SERIES_FIELDS)
            for p in points:
                writer.writerow([_cell(getattr(p, name)) for name in SERIES_FIELDS])
        return out
    if format == "parquet":
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError as exc:
            raise InputError("export --format parquet needs pyarrow "
                             "(pip install 'gimbal-hil[parquet]')") from exc
        columns = {name: [getattr(p, name) for p in points] for name in SERIES_FIELDS}
        pq.write_table(pa.table(columns), out)
        return out
    raise InputError(f"export: format '{format}' is not csv or parquet")


def _cell(value: object) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if hasattr(value, "isoformat"):
        return str(value.isoformat())
    return str(value)
