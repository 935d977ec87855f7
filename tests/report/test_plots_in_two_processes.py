"""The certificate's plots drawn half in a forked child (a second core) are the plots drawn
in one process: the same protocols, the same PNG bytes, the same problems. Run in a fresh
interpreter: a pytest-xdist worker has more than one thread, and forks nothing."""

from __future__ import annotations

import subprocess
import sys

from tests.report.runs import Run

SCRIPT = """
import json, sys
from pathlib import Path
import hil.parallel
from hil.report.documents import _plots
from hil.report.view import certificate_view

unit = Path(sys.argv[1])

def drawn():
    cert = json.loads((unit / "certificate.json").read_text(encoding="utf-8"))
    view = certificate_view(cert)
    problems = []
    pngs = _plots(cert, unit, view, problems)
    return pngs, problems, [p["plot"] for p in view["protocols"]]

assert hil.parallel.can_fork(), "one thread, two cores: the child must be forked"
forked = drawn()
hil.parallel.can_fork = lambda: False
alone = drawn()
assert len(forked[0]) >= 10, sorted(forked[0])
assert forked == alone, "the forked half drew something else"
print("same", len(forked[0]))
"""


def test_the_forked_half_draws_what_one_process_draws(elevation_run: Run) -> None:
    done = subprocess.run([sys.executable, "-c", SCRIPT, str(elevation_run.unit_dir)],
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("same ")
