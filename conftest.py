"""Repo-level pytest wiring only: what is not collected, and how pytest-xdist shares the
work. The gimbal-hil plugin loads through its ``pytest11`` entry point; test-only settings
(hypothesis profiles) live in tests/."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import pytest

collect_ignore = ["benchmarks", "docs", "build"]

ROOT = Path(__file__).parent
SLOW_FILE = "pytestmark = pytest.mark.slow"


@functools.cache
def _slow_file(path: str) -> bool:
    """A test file marked slow as a whole (a population, a Hypothesis search of runs)."""
    file = ROOT / path
    return file.is_file() and SLOW_FILE in file.read_text(encoding="utf-8")


def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """``-n N``: each test file to one worker (its module fixtures, a calibration or a
    population, made once), and the calibration's protocols together, in the profile's
    order (one session, one certificate); files marked slow first, so that none of them
    is the last thing running. Another ``--dist`` (loadfile, loadgroup, ...) is kept."""
    if config.option.dist != "load":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class ByFile(LoadScopeScheduling):  # type: ignore[misc]
        def _split_scope(self, nodeid: str) -> str:
            path = nodeid.split("::", 1)[0]
            return "protocols/" if path.startswith("protocols/") else path

        def _assign_work_unit(self, node: Any) -> None:
            slow = next((scope for scope in self.workqueue if _slow_file(scope)), None)
            if slow is not None:
                self.workqueue.move_to_end(slow, last=False)
            super()._assign_work_unit(node)

    return ByFile(config, log)
