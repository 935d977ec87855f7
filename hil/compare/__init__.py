"""``gimbal-hil compare``: a baseline calibration against a candidate (firmware regression).

Pure functions over certificate JSON: :mod:`certificates` reads and checks them,
:mod:`budget` keeps only what the two runs do not share, :mod:`statistics` holds the
Student-t and Holm procedures, :mod:`verdict` judges each result, :mod:`report` prints it.

The names below load on first use (PEP 562), so that importing :mod:`hil.compare.cli` for
its arguments (``gimbal-hil --help``) does not load scipy.stats.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from hil.compare.certificates import Certificate, load_side, read_certificate
    from hil.compare.verdict import Comparison, Row, Verdict, compare_sides

_HOME = {"Certificate": "certificates", "load_side": "certificates",
         "read_certificate": "certificates", "Comparison": "verdict", "Row": "verdict",
         "Verdict": "verdict", "compare_sides": "verdict"}

__all__ = ["Certificate", "Comparison", "Row", "Verdict", "compare_sides", "load_side",
           "read_certificate"]


def __getattr__(name: str) -> Any:
    if name not in _HOME:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f"{__name__}.{_HOME[name]}"), name)
