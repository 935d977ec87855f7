"""Resource budgets stated up front: memory (from the planned samples, before allocating)
and disk (before the first motion), and the one-line error of a write that failed.

Vocabulary level: imports nothing of gimbal-hil but :mod:`hil.errors`.
"""

from __future__ import annotations

import contextlib
import errno
import os
import resource
import shutil
from collections.abc import Iterator
from pathlib import Path

from hil.errors import HilError, InputError

MEMORY_BUDGET_ENV = "GIMBAL_HIL_MEMORY_BUDGET_MB"
MEMORY_BUDGET_FRACTION = 0.5  # of the physical memory (or the cgroup's limit, if lower)
MIB = 1024 * 1024

# calibrate: bytes of memory per sample of the largest protocol's excitations while it runs
# and is analysed (command, recording columns, the CSV text being written, the fits);
# the simulator's calibration peaks at 385 MB resident with 83 k samples in its largest
# protocol (~160 MB of it imports): ~2.7 kB/sample all in, ~0.9 kB above the imports
CALIBRATE_BYTES_PER_SAMPLE = 3072
# disk: a recording row as CSV text, per column (9 significant digits, sign, exponent, comma;
# gzip makes it ~4x smaller, not counted: the margin is kept)
CSV_BYTES_PER_VALUE = 12
RECORDING_COLUMNS = 7  # time, command, position, velocity, torque, current, one spare
DOCUMENTS_BYTES = 16 * MIB  # certificate JSON/TXT/HTML/PDF, controller files (~3 MB measured)
DISK_MARGIN = 1.5  # on the estimate: temporary files of atomic writes, history, logs


class StorageError(HilError):
    """A recording, certificate or derived file could not be written (a full disk, a
    read-only or forbidden folder): the calibration stops at once."""


def storage_error(exc: OSError, path: Path | str) -> StorageError:
    """The one line for a failed write of ``path``: what the system said and what to do."""
    name = errno.errorcode.get(exc.errno or 0, "")
    why = exc.strerror or str(exc)
    hint = {errno.ENOSPC: "free space on the disk",
            errno.EDQUOT: "free space within the quota",
            errno.EROFS: "the disk is read-only: choose another --out",
            errno.EACCES: "no permission to write there: choose another --out",
            errno.EPERM: "no permission to write there: choose another --out"}.get(
                exc.errno or 0, "check the output folder")
    return StorageError(f"cannot write {path}: {why}{f' ({name})' if name else ''}; "
                        f"the calibration stopped: {hint}")


# -- memory ------------------------------------------------------------------------------
def physical_memory_bytes() -> int:
    """The machine's memory, or the cgroup's limit when lower (0: unknown)."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (OSError, ValueError):
        total = 0
    for limit in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        with contextlib.suppress(OSError, ValueError):
            value = int(Path(limit).read_text(encoding="ascii").strip())
            if 0 < value < (total or value + 1):
                total = value
    return max(total, 0)


def memory_budget_bytes() -> tuple[int, str]:
    """The memory budget and how it was set (for messages).

    ``GIMBAL_HIL_MEMORY_BUDGET_MB`` (MiB) when set, else :data:`MEMORY_BUDGET_FRACTION` of
    :func:`physical_memory_bytes` (4 GiB when that is unknown).

    Raises
    ------
    InputError
        The environment variable is not a positive number.
    """
    text = os.environ.get(MEMORY_BUDGET_ENV, "").strip()
    if text:
        try:
            value_mb = float(text)
        except ValueError:
            value_mb = float("nan")
        if not value_mb > 0 or value_mb == float("inf"):
            raise InputError(f"must be a positive number of MiB, not {text!r}",
                             source=MEMORY_BUDGET_ENV)
        return int(value_mb * MIB), f"{MEMORY_BUDGET_ENV}={text}"
    physical = physical_memory_bytes()
    if physical <= 0:
        return 4096 * MIB, "4 GiB: the physical memory is unknown"
    return (int(physical * MEMORY_BUDGET_FRACTION),
            f"{MEMORY_BUDGET_FRACTION:.0%} of {physical / MIB:.0f} MiB physical memory; "
            f"set {MEMORY_BUDGET_ENV} to change it")


def check_memory(needed_bytes: float, what: str, *, source: str | None = None) -> None:
    """Refuse ``what`` in one line when it needs more than the memory budget.

    Raises
    ------
    InputError
        ``needed_bytes`` exceeds :func:`memory_budget_bytes`.
    """
    budget, how = memory_budget_bytes()
    if needed_bytes > budget:
        raise InputError(f"{what} needs about {needed_bytes / MIB:,.0f} MiB of memory, more "
                         f"than the budget of {budget / MIB:,.0f} MiB ({how})", source=source)


@contextlib.contextmanager
def address_space_bounded(what: str, *, source: str | None = None) -> Iterator[None]:
    """Inside the block the process may grow by at most the memory budget (a soft
    ``RLIMIT_AS`` over what it maps now): an allocation beyond it raises ``MemoryError``,
    refused here as one :class:`InputError` naming ``what``; the limit returns after.
    For work whose size is only known by doing it (building a profile's excitations)."""
    budget, how = memory_budget_bytes()
    try:
        soft, hard = resource.getrlimit(resource.RLIMIT_AS)
        mapped = _mapped_bytes()
    except (OSError, ValueError):
        yield  # no limit to set: unbounded as before
        return
    bound = mapped + budget
    if hard != resource.RLIM_INFINITY:
        bound = min(bound, hard)
    if soft != resource.RLIM_INFINITY:
        bound = min(bound, soft)
    resource.setrlimit(resource.RLIMIT_AS, (bound, hard))
    try:
        yield
    except MemoryError:
        raise InputError(f"{what} needs more memory than the budget of {budget / MIB:,.0f} "
                         f"MiB ({how})", source=source) from None
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def _mapped_bytes() -> int:
    """The process' virtual size now (``VmSize`` of ``/proc/self/status``)."""
    for line in Path("/proc/self/status").read_text(encoding="ascii").splitlines():
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
    raise ValueError("no VmSize")


# -- disk --------------------------------------------------------------------------------
def recording_bytes(samples: float, *, columns: int = RECORDING_COLUMNS) -> float:
    """Upper estimate of ``samples`` rows as CSV text (before gzip)."""
    return samples * columns * CSV_BYTES_PER_VALUE


def check_disk(folder: Path, *, samples: float) -> int:
    """Refuse a calibration whose recordings (``samples`` rows in all) and documents would
    not fit in the free space of ``folder``'s file system, with :data:`DISK_MARGIN`.

    Returns
    -------
    int
        The bytes needed (estimate with margin).

    Raises
    ------
    InputError
        One line naming the folder, the free and the needed bytes.
    """
    needed = int((recording_bytes(samples) + DOCUMENTS_BYTES) * DISK_MARGIN)
    existing = folder.absolute()
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    try:
        free = shutil.disk_usage(existing).free
    except OSError as exc:
        raise InputError(f"cannot read the free space: {exc.strerror or exc}",
                         source=str(folder)) from None
    if free < needed:
        raise InputError(
            f"{free:,} bytes free ({free / MIB:,.1f} MiB), the calibration needs about "
            f"{needed:,} bytes ({needed / MIB:,.1f} MiB: {samples:,.0f} samples of "
            f"recordings at {RECORDING_COLUMNS * CSV_BYTES_PER_VALUE} B each and the "
            f"documents, x{DISK_MARGIN:g} margin): free space or choose another --out",
            source=str(folder))
    return needed
