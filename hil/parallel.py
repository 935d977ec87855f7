"""Half of a long piece of work on a second core: a forked child computes bytes while this
process goes on, for the two places where one process waits on pure-Python work that splits
in two (formatting a long recording's rows, drawing a certificate's plots).

Forking is safe only in a process with one thread (a lock another thread holds would stay
held in the child forever), so a process with more, or a machine with one core, does all
the work itself.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def can_fork() -> bool:
    """A child can be forked safely and would have a core of its own."""
    return (hasattr(os, "fork") and (os.cpu_count() or 1) >= 2
            and threading.active_count() == 1)


def forked_bytes(work: Callable[[], bytes], meanwhile: Callable[[], T]) -> tuple[T, bytes | None]:
    """``meanwhile()`` here while a forked child computes ``work()``.

    Parameters
    ----------
    work : callable
        Run in the child; what it returns comes back through a pipe.
    meanwhile : callable
        Run here at the same time.

    Returns
    -------
    tuple
        ``meanwhile()``'s result, and ``work()``'s bytes or ``None`` when no child could be
        forked (:func:`can_fork`) or it failed: the caller then does that work itself.
    """
    if not can_fork():
        return meanwhile(), None
    read_end, write_end = os.pipe()
    child = os.fork()
    if child == 0:  # pragma: no cover (the child exits without returning)
        status = 1
        try:
            os.close(read_end)
            with os.fdopen(write_end, "wb") as pipe:
                pipe.write(work())
            status = 0
        finally:
            os._exit(status)
    os.close(write_end)
    try:
        result = meanwhile()
    finally:  # the child's bytes are read and the child reaped whatever happened here
        with os.fdopen(read_end, "rb") as pipe:
            data = pipe.read()
        _, status = os.waitpid(child, 0)
    return result, data if status == 0 else None
