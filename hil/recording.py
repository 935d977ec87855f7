"""The Recording type and its CSV reader/writer (``shared/recording-format.md``, v1).

A recording is one sampled log of one axis. Columns keep their file names, which carry
their SI unit (``torque_nm``, ``position_rad``...). Rotary and linear axes share the type:
``position``/``velocity``/``effort`` return the axis' own columns.
"""

from __future__ import annotations

import functools
import gzip
import hashlib
import logging
import os
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from hil.budget import memory_budget_bytes
from hil.errors import RecordingError
from hil.parallel import forked_bytes

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
AxisKind = Literal["rotary", "linear"]

ROTARY_REQUIRED = ("time_s", "position_rad", "velocity_rad_s", "torque_nm")
LINEAR_REQUIRED = ("time_s", "position_m", "velocity_m_s", "force_n")
ROTARY_OPTIONAL = (
    "velocity_cmd_rad_s",
    "position_cmd_rad",
    "current_a",
    "elevation_rad",
    "load_torque_nm",
)
LINEAR_OPTIONAL = ("velocity_cmd_m_s", "position_cmd_m", "current_a")
MIN_SAMPLES = 100
GAP_FACTOR = 5.0
SATURATION_FRACTION = 0.01
#: the acquisition path of a recording with a row per control period (the simulator, a
#: drive recorder): the one the method map (``fixtures/method_bias.toml``) was measured on
EVERY_CONTROL_PERIOD = "every control period"


@dataclass(frozen=True, slots=True, kw_only=True)
class Recording:
    """One axis log. ``columns`` maps file column names (with units) to float arrays."""

    columns: Mapping[str, FloatArray]
    metadata: Mapping[str, str] = field(default_factory=dict)
    source: str = "<memory>"
    warnings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        names = set(self.columns)
        kind = _axis_kind(names, self.source)
        required = ROTARY_REQUIRED if kind == "rotary" else LINEAR_REQUIRED
        lengths = {len(self.columns[name]) for name in names}
        if len(lengths) != 1:
            raise RecordingError("columns have different lengths", source=self.source)
        for name in required:
            if name not in names:
                raise RecordingError("missing required column", source=self.source, column=name)

    # -- axis-independent access -------------------------------------------------------
    @property
    def axis_kind(self) -> AxisKind:
        return _axis_kind(set(self.columns), self.source)

    @property
    def time_s(self) -> FloatArray:
        return self.columns["time_s"]

    @property
    def position(self) -> FloatArray:
        """Position in rad (rotary) or m (linear)."""
        return self.columns["position_rad" if self.axis_kind == "rotary" else "position_m"]

    @property
    def velocity(self) -> FloatArray:
        """Velocity in rad/s (rotary) or m/s (linear), as the drive reports it."""
        return self.columns["velocity_rad_s" if self.axis_kind == "rotary" else "velocity_m_s"]

    @property
    def effort(self) -> FloatArray:
        """Torque in N·m (rotary) or force in N (linear)."""
        return self.columns["torque_nm" if self.axis_kind == "rotary" else "force_n"]

    @property
    def velocity_cmd(self) -> FloatArray | None:
        name = "velocity_cmd_rad_s" if self.axis_kind == "rotary" else "velocity_cmd_m_s"
        return self.columns.get(name)

    @property
    def units(self) -> dict[str, str]:
        """Unit labels for position, velocity, effort of this axis kind."""
        if self.axis_kind == "rotary":
            return {"position": "rad", "velocity": "rad/s", "effort": "N·m"}
        return {"position": "m", "velocity": "m/s", "effort": "N"}

    def __len__(self) -> int:
        return len(self.time_s)

    @property
    def duration_s(self) -> float:
        return float(self.time_s[-1] - self.time_s[0])

    @property
    def sample_rate_hz(self) -> float:
        """Median sample rate; sampling need not be uniform."""
        return float(1.0 / np.median(np.diff(self.time_s)))

    def slice(self, start: int, stop: int) -> Recording:
        """Samples ``start:stop`` as a new recording (metadata kept)."""
        return Recording(
            columns={k: v[start:stop] for k, v in self.columns.items()},
            metadata=self.metadata,
            source=f"{self.source}[{start}:{stop}]",
            warnings=self.warnings,
        )


def _axis_kind(names: set[str], source: str) -> AxisKind:
    rotary = {"position_rad", "velocity_rad_s", "torque_nm"} & names
    linear = {"position_m", "velocity_m_s", "force_n"} & names
    if rotary and linear:
        raise RecordingError(
            f"mixes rotary columns {sorted(rotary)} with linear columns {sorted(linear)}",
            source=source,
        )
    return "linear" if linear else "rotary"


# -- reading ------------------------------------------------------------------------------
READ_BYTES_PER_ROW = 1536  # memory of reading one row (text, cells, floats): ~1.1 kB measured
MAX_ROW_TEXT_BYTES = 1024  # a row's text beyond which a file is no recording (a gzip bomb)
READ_CHUNK_BYTES = 1 << 20


def _read_text(path: Path, *, bytes_per_row: int = READ_BYTES_PER_ROW) -> list[str]:
    source = str(path)
    try:
        raw = _bounded_bytes(path, bytes_per_row=bytes_per_row)
        return raw.decode("utf-8-sig").splitlines()  # a byte-order mark is no column name
    except (OSError, EOFError, gzip.BadGzipFile) as exc:
        raise RecordingError(f"cannot read file: {exc}", source=source) from exc
    except UnicodeDecodeError as exc:
        raise RecordingError("file is not UTF-8 text", source=source) from exc


def _bounded_bytes(path: Path, *, bytes_per_row: int) -> bytes:
    """The file's bytes (decompressed), read in chunks and refused once its rows would take
    more than the memory budget (``bytes_per_row`` each, reading included) or its text more
    than :data:`MAX_ROW_TEXT_BYTES` per allowed row: rows are counted before anything is
    held whole, a gzip file is decompressed no further than the limit.

    Raises
    ------
    RecordingError
        Past the limit (one line: rows or bytes seen, the budget).
    OSError, EOFError, gzip.BadGzipFile
        The file cannot be read.
    """
    budget, how = memory_budget_bytes()
    per_row = max(bytes_per_row, READ_BYTES_PER_ROW)
    max_rows = max(MIN_SAMPLES, budget // per_row)
    max_bytes = max_rows * MAX_ROW_TEXT_BYTES
    chunks: list[bytes] = []
    rows = size = 0
    with (gzip.open(path, "rb") if path.suffix == ".gz" else path.open("rb")) as stream:
        while chunk := stream.read(READ_CHUNK_BYTES):
            rows += chunk.count(b"\n")
            size += len(chunk)
            if rows > max_rows or size > max_bytes:
                seen = f"{rows:,} rows" if rows > max_rows else f"{size:,} bytes of text"
                raise RecordingError(
                    f"more than {seen} (read so far): over the limit of {max_rows:,} rows "
                    f"({per_row:,} B of memory each within a budget of "
                    f"{budget / 2**20:,.0f} MiB: {how}); not read further", source=str(path))
            chunks.append(chunk)
    return b"".join(chunks)


def read_recording(path: str | Path, *, log_warnings: bool = True,
                   bytes_per_row: int = READ_BYTES_PER_ROW) -> Recording:
    """Read a recording, refusing bad input with file, line and column named; the format's
    warnings (gaps, saturation, a still position) are logged unless ``log_warnings`` is
    false, and kept on the recording either way.

    Raises
    ------
    RecordingError
        Missing required column, duplicate column, non-numeric or non-finite value, time
        not strictly increasing, fewer than 100 samples, unreadable file; more rows than
        the memory budget (:func:`hil.budget.memory_budget_bytes`) allows at
        ``bytes_per_row`` each (the reader's own by default; a caller that needs more per
        row, e.g. ``diagnose``, says so), refused before the file is held whole.
    """
    path = Path(path)
    return parse_recording(_read_text(path, bytes_per_row=bytes_per_row), source=str(path),
                           log_warnings=log_warnings)


@dataclass(frozen=True, slots=True)
class _Table:
    metadata: dict[str, str]
    header: list[str]
    cells: NDArray[np.str_]
    line_numbers: Sequence[int]
    numeric: FloatArray | None = None  # every cell, when all are finite numbers

    def column(self, position: int, name: str, source: str, *, strict: bool
               ) -> FloatArray | None:
        """Column ``position`` as floats (see :func:`_to_float`)."""
        if self.numeric is not None:
            return self.numeric[:, position].copy()
        return _to_float(self.cells[:, position], name, self.line_numbers, source,
                         strict=strict)


def _parse_table(lines: list[str], *, source: str) -> _Table:
    """Metadata, header and cells of a CSV with ``# key: value`` lines before the header."""
    metadata: dict[str, str] = {}
    header_index = None
    for index, line in enumerate(lines):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            key, sep, value = stripped.lstrip("#").partition(":")
            if sep:
                metadata[key.strip()] = value.strip()
            continue
        header_index = index
        break
    if header_index is None:
        raise RecordingError("no header row", source=source)
    header = [name.strip() for name in lines[header_index].split(",")]
    seen: set[str] = set()
    for name in header:
        if name in seen:
            raise RecordingError("duplicate column name", source=source, column=name)
        seen.add(name)
    numeric = _numeric_body(lines[header_index + 1 :], len(header))
    if numeric is not None:  # every line a plain row of numbers: no line to name
        first = header_index + 2
        return _Table(metadata, header, np.empty((0, len(header)), dtype=str),
                      range(first, first + numeric.shape[0]), numeric)
    numbered = [
        (number, line)
        for number, line in enumerate(lines[header_index + 1 :], start=header_index + 2)
        if line.strip()
    ]
    rows = [line.split(",") for _, line in numbered]
    for row, (number, _) in zip(rows, numbered, strict=True):
        if len(row) != len(header):
            raise RecordingError(
                f"has {len(row)} fields, the header has {len(header)}", source=source, line=number
            )
    if len(rows) < MIN_SAMPLES:
        raise RecordingError(
            f"has {len(rows)} samples, at least {MIN_SAMPLES} are needed", source=source
        )
    cells = np.array(rows, dtype=str)
    return _Table(metadata, header, cells, [number for number, _ in numbered])


def _numeric_body(body: list[str], width: int) -> FloatArray | None:
    """The rows as one float array, parsed in C, when every line is ``width`` finite
    numbers and there are enough of them; otherwise None, and the line-by-line reader
    finds and names what is wrong (a blank line, a text cell, a short row)."""
    if len(body) < MIN_SAMPLES or not all(body):
        return None
    try:
        values = np.loadtxt(body, delimiter=",", dtype=np.float64, ndmin=2, comments=None)
    except ValueError:
        return None
    if values.shape != (len(body), width) or not np.isfinite(values).all():
        return None
    return values


def _strictly_increasing(time_s: FloatArray, table: _Table, source: str) -> None:
    bad = np.flatnonzero(np.diff(time_s) <= 0)
    if bad.size:
        raise RecordingError(
            "time is not strictly increasing",
            source=source,
            line=table.line_numbers[int(bad[0]) + 1],
            column="time_s",
        )


def parse_recording(lines: list[str], *, source: str, log_warnings: bool = True) -> Recording:
    """Parse the lines of a recording file (see :func:`read_recording`)."""
    table = _parse_table(lines, source=source)
    names = set(table.header)
    kind = _axis_kind(names, source)
    required = ROTARY_REQUIRED if kind == "rotary" else LINEAR_REQUIRED
    for name in required:
        if name not in names:
            raise RecordingError("missing required column", source=source, column=name)
    known = set(required) | set(ROTARY_OPTIONAL if kind == "rotary" else LINEAR_OPTIONAL)
    columns: dict[str, FloatArray] = {}
    for position, name in enumerate(table.header):
        values = table.column(position, name, source, strict=name in known)
        if values is not None:
            columns[name] = values
    _strictly_increasing(columns["time_s"], table, source)
    recording = Recording(columns=columns, metadata=table.metadata, source=source)
    warnings = tuple(check_recording(recording))
    for message in warnings if log_warnings else ():
        log.warning("%s: %s", source, message)
    return Recording(columns=columns, metadata=table.metadata, source=source, warnings=warnings)


def read_command_csv(path: str | Path, *, allowed: tuple[str, ...]) -> dict[str, FloatArray]:
    """A command file: ``time_s`` and exactly one of the ``allowed`` command columns."""
    path = Path(path)
    source = str(path)
    table = _parse_table(_read_text(path), source=source)
    present = [name for name in table.header if name in allowed]
    if "time_s" not in table.header:
        raise RecordingError("missing required column", source=source, column="time_s")
    if len(present) != 1:
        raise RecordingError(
            f"needs exactly one command column of {', '.join(allowed)}; found {present or 'none'}",
            source=source,
        )
    columns: dict[str, FloatArray] = {}
    for name in ("time_s", present[0]):
        values = table.column(table.header.index(name), name, source, strict=True)
        assert values is not None  # strict conversion returns values or raises
        columns[name] = values
    _strictly_increasing(columns["time_s"], table, source)
    return columns


def _to_float(
    text: NDArray[np.str_], name: str, line_numbers: Sequence[int], source: str, *, strict: bool
) -> FloatArray | None:
    """Column to floats; a known column must be numeric and finite, an unknown one is skipped."""
    try:
        values = text.astype(np.float64)
    except ValueError as exc:
        if not strict:
            return None
        for index, cell in enumerate(text):
            try:
                float(cell)
            except ValueError:
                raise RecordingError(
                    f"non-numeric value {cell.strip()!r}",
                    source=source,
                    line=line_numbers[index],
                    column=name,
                ) from exc
        raise  # pragma: no cover - astype failed but every cell parsed
    finite = np.isfinite(values)
    if not finite.all():
        if not strict:
            return None
        index = int(np.flatnonzero(~finite)[0])
        raise RecordingError(
            f"non-finite value {text[index].strip()!r}",
            source=source,
            line=line_numbers[index],
            column=name,
        )
    return values


def check_recording(recording: Recording) -> list[str]:
    """Warnings the format asks for: gaps, saturation, a position that never changes."""
    messages: list[str] = []
    steps = np.diff(recording.time_s)
    period = float(np.median(steps))
    gaps = np.flatnonzero(steps > GAP_FACTOR * period)
    if gaps.size:
        messages.append(
            f"{gaps.size} gap(s) longer than {GAP_FACTOR:g} sample periods "
            f"(first at t = {recording.time_s[gaps[0]]:.6g} s, "
            f"longest {steps[gaps].max():.6g} s)"
        )
    fraction, clip = saturation_fraction(recording.effort)
    if fraction > SATURATION_FRACTION:
        messages.append(
            f"effort sits at its clip value {clip:.6g} for {100 * fraction:.1f} % of samples "
            "(saturation)"
        )
    if np.ptp(recording.position) == 0.0:
        messages.append("position never changes")
    return messages


def saturation_fraction(effort: FloatArray) -> tuple[float, float]:
    """Fraction of samples at the extreme value of ``effort`` (either sign) and that value."""
    best_fraction, best_clip = 0.0, 0.0
    for clip in (float(np.max(effort)), float(np.min(effort))):
        if clip == 0.0:
            continue
        fraction = float(np.mean(effort == clip))
        if fraction > best_fraction:
            best_fraction, best_clip = fraction, clip
    return best_fraction, best_clip


def saturated_mask(effort: FloatArray) -> NDArray[np.bool_]:
    """Samples at a clip value that is held for more than 1 % of the samples."""
    mask = np.zeros(effort.shape, dtype=bool)
    for clip in (float(np.max(effort)), float(np.min(effort))):
        at_clip = effort == clip
        if clip != 0.0 and at_clip.mean() > SATURATION_FRACTION:
            mask |= at_clip
    return mask


# -- writing ------------------------------------------------------------------------------
def write_recording(recording: Recording, path: str | Path) -> str:
    """Write ``recording`` as CSV (gzip when the name ends in ``.gz``); return its SHA-256."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    names = _ordered(recording.columns)
    lines = [f"# {key}: {value}" for key, value in recording.metadata.items()]
    lines.append(",".join(names))
    payload = ("\n".join(lines) + "\n").encode("utf-8") + _rows_csv(
        [recording.columns[name] for name in names])
    if path.suffix == ".gz":
        payload = gzip.compress(payload, compresslevel=3, mtime=0)
    write_atomic(path, payload)
    return hashlib.sha256(payload).hexdigest()


#: rows from which half of them are formatted in a forked child (where one can be forked)
FORK_ROWS = 200_000


def _format_rows(columns: Sequence[FloatArray], start: int, stop: int) -> str:
    """Rows ``start:stop`` as CSV text, ``%.9g`` each value (one format per row: twice as
    fast as one per value)."""
    row_format = ",".join(["%.9g"] * len(columns))
    return "\n".join(map(row_format.__mod__, zip(
        *(c[start:stop].tolist() for c in columns), strict=True)))


def _rows_csv(columns: Sequence[FloatArray]) -> bytes:
    """Every row as CSV, each ending in a newline. Formatting is most of a long recording's
    writing time (2.9 million values for two minutes at 4 kHz: about a second), so from
    :data:`FORK_ROWS` rows on the second half is formatted on another core
    (:func:`hil.parallel.forked_bytes`); the bytes are the same."""
    rows = len(columns[0]) if columns else 0
    if rows == 0:
        return b""
    if rows < FORK_ROWS:
        return _format_rows(columns, 0, rows).encode("utf-8") + b"\n"
    half = rows // 2
    first, second = forked_bytes(lambda: _format_rows(columns, half, rows).encode("utf-8"),
                                 lambda: _format_rows(columns, 0, half).encode("utf-8"))
    rest = _format_rows(columns, half, rows).encode("utf-8") if second is None else second
    return b"".join((first, b"\n", rest, b"\n"))


def write_atomic(path: str | Path, payload: bytes) -> None:
    """Write ``payload`` as ``path`` all at once or not at all: a temporary file in the same
    folder, flushed to disk, renamed over ``path`` (a stop or a full disk leaves the old
    file or none, never a truncated one).

    Raises
    ------
    OSError
        The folder is not writable, the disk is full (the temporary file is removed).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.",
                                         suffix=".tmp")
    try:
        os.fchmod(handle, 0o666 & ~_umask())  # mkstemp's 0600 is not what a file gets
        with os.fdopen(handle, "wb") as stream:
            stream.write(payload)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    _fsync_folder(path.parent)


@functools.cache
def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _fsync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable (where the system allows opening a folder)."""
    try:
        descriptor = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(descriptor)
    except OSError:
        pass
    finally:
        os.close(descriptor)


def _ordered(columns: Iterable[str]) -> list[str]:
    names = list(columns)
    order = dict.fromkeys(ROTARY_REQUIRED + LINEAR_REQUIRED + ROTARY_OPTIONAL + LINEAR_OPTIONAL)
    known = [name for name in order if name in names]
    return known + [name for name in names if name not in known]


def sha256_file(path: str | Path) -> str:
    """SHA-256 of a file's bytes (for the certificate's raw-data hashes)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()
