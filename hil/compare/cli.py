"""``gimbal-hil compare BASELINE CANDIDATE [--json OUT] [--markdown OUT]
[--allow-different-units] [--alpha 0.05]``.

Exit code 0: nothing worse; 1: a result WORSE, CHANGED or MISSING; 2: bad input (one line
on stderr naming what and where).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from hil.errors import InputError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``compare``'s arguments to ``parser``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        Gets ``baseline``, ``candidate``, ``--json``, ``--markdown``,
        ``--allow-different-units``, ``--alpha`` and ``--repeatability``.
    """
    parser.add_argument("baseline", type=Path,
                        help="certificate.json, or a directory of SERIAL/certificate.json")
    parser.add_argument("candidate", type=Path, help="the same, after the change")
    parser.add_argument("--json", metavar="OUT.json", type=Path,
                        help="write the comparison here, full precision (default: not written)")
    parser.add_argument("--markdown", metavar="OUT.md", type=Path,
                        help="write a table for a pull-request comment (default: not written)")
    parser.add_argument("--allow-different-units", action="store_true",
                        help="compare different serials, unit types or profiles (default: "
                             "refused)")
    parser.add_argument("--alpha", type=float, default=0.05,
                        help="family-wise error rate of the Holm procedure "
                             "(default: %(default)s)")
    parser.add_argument("--repeatability", metavar="MAP.toml|off", default=None,
                        help="run-to-run scatter beyond the budgets (default: the shipped "
                             "fixtures/compare_repeatability.toml; 'off': none)")


def run(args: argparse.Namespace) -> int:
    """Compare, print the table, write the files asked for.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed by a parser that :func:`add_arguments` set up.

    Returns
    -------
    int
        0 nothing worse, 1 something WORSE, CHANGED or MISSING. Bad input raises
        :class:`~hil.errors.InputError` (the command line prints it and returns 2).
    """
    # imported here, not at the top: `gimbal-hil --help` must not load scipy.stats
    from hil.compare.certificates import load_side
    from hil.compare.repeatability import NO_MAP, load_repeatability
    from hil.compare.report import as_json, render_markdown, render_text
    from hil.compare.verdict import compare_sides

    repeatability = (NO_MAP if args.repeatability == "off"
                     else load_repeatability(None if args.repeatability is None
                                             else Path(args.repeatability)))
    comparison = compare_sides(load_side(args.baseline), load_side(args.candidate),
                               alpha=args.alpha,
                               allow_different_units=args.allow_different_units,
                               repeatability=repeatability)
    for warning in comparison.warnings:
        print(f"gimbal-hil compare: warning: {warning}", file=sys.stderr)
    print(render_text(comparison), end="")
    if args.json is not None:
        _write(args.json, json.dumps(as_json(comparison), indent=2) + "\n")
    if args.markdown is not None:
        _write(args.markdown, render_markdown(comparison))
    return comparison.exit_code


def _write(path: Path, text: str) -> None:
    try:
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror or exc}", source=str(path)) from exc
