"""Repo-level pytest wiring only: what is not collected, and how pytest-xdist shares the
work. The gimbal-hil plugin loads through its ``pytest11`` entry point; test-only settings
(hypothesis profiles) live in tests/."""

from __future__ import annotations

from typing import Any

import pytest

collect_ignore = ["benchmarks", "docs", "build"]


def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """``-n N``: each test file to one worker (its module fixtures, a calibration or a
    population, made once), and the calibration's protocols together, in the profile's
    order (one session, one certificate); a ``--dist`` given is kept."""
    if config.option.dist != "load":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class ByFile(LoadScopeScheduling):  # type: ignore[misc]
        def _split_scope(self, nodeid: str) -> str:
            path = nodeid.split("::", 1)[0]
            return "protocols/" if path.startswith("protocols/") else path

    return ByFile(config, log)
