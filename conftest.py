"""Repo-level pytest wiring only: what is not collected, and how pytest-xdist shares the
work. The gimbal-hil plugin loads through its ``pytest11`` entry point; test-only settings
(hypothesis profiles) live in tests/."""

from __future__ import annotations

import functools
import re
from pathlib import Path
from typing import Any

import pytest

collect_ignore = ["benchmarks", "docs", "build"]

ROOT = Path(__file__).parent
#: A test file marked slow as a whole, with the machine time it takes on one core if stated
#: (``pytestmark = pytest.mark.slow(seconds=240)``, or in a list, on a continuation line too).
SLOW_FILE = re.compile(
    r"^pytestmark = (?:[^\n]*\n[ \t]+)*?[^\n]*?pytest\.mark\.slow(?:\(seconds=(\d+)\))?", re.M)


@functools.cache
def _slow_seconds(path: str) -> int:
    """How long a test file marked slow as a whole takes (1 when it does not say; 0 for a
    file not marked slow)."""
    file = ROOT / path
    found = SLOW_FILE.search(file.read_text(encoding="utf-8")) if file.is_file() else None
    return 0 if found is None else int(found.group(1) or 1)


def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """``-n N``: each test file to one worker (its module fixtures, a calibration or a
    population, made once), and the calibration's protocols together, in the profile's
    order (one session, one certificate); files marked slow first, the longest first, so
    that none of them is the last thing running (longest processing time first: two
    workers finish within the longest file's time of each other). Another ``--dist``
    (loadfile, loadgroup, ...) is kept."""
    if config.option.dist != "load":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class ByFile(LoadScopeScheduling):  # type: ignore[misc]
        def _split_scope(self, nodeid: str) -> str:
            path = nodeid.split("::", 1)[0]
            return "protocols/" if path.startswith("protocols/") else path

        def _assign_work_unit(self, node: Any) -> None:
            slow = max(self.workqueue, key=_slow_seconds, default=None)
            if slow is not None and _slow_seconds(slow):
                self.workqueue.move_to_end(slow, last=False)
            super()._assign_work_unit(node)

    return ByFile(config, log)
