"""``gimbal-hil diagnose REC.csv[.gz] [--validate OTHER] --json OUT.json [--plots DIR]``.

Exit code 0 whether or not causes are found; 2 with one clear line on stderr for a bad
file or data that cannot support the fit.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from hil.errors import HilError, InputError

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``diagnose``'s arguments to ``parser``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        Gets ``recording``, ``--validate``, ``--json`` (required), ``--plots``,
        ``--profile-out`` and ``--cutoff-hz``.
    """
    parser.add_argument("recording", help="recording to explain (.csv or .csv.gz)")
    parser.add_argument("--validate", metavar="OTHER",
                        help="second recording of the same axis: judge every gain on it "
                             "(default: the recording's own held-out part)")
    parser.add_argument("--json", metavar="OUT.json", required=True,
                        help="write the report here")
    parser.add_argument("--plots", metavar="DIR",
                        help="write PNG plots into this directory (default: no plots)")
    parser.add_argument("--profile-out", metavar="OUT.toml",
                        help="write the extended model as a unit profile, TOML (default: "
                             "not written)")
    parser.add_argument("--cutoff-hz", type=float, default=None,
                        help="analysis bandwidth (default: sample rate / 8, at most 250 Hz)")


def run(args: argparse.Namespace) -> int:
    """Diagnose, write the JSON report (and the profile and plots when asked), print a line.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed by a parser that :func:`add_arguments` set up.

    Returns
    -------
    int
        The exit code: 0, found causes or not; 2 after printing a :class:`HilError` on
        stderr (a bad file, data that cannot support the fit).
    """
    # heavy imports here, so that `gimbal-hil --help` stays fast
    from hil.diagnose.core import DIAGNOSE_BYTES_PER_ROW, diagnose
    from hil.diagnose.profile_out import write_profile
    from hil.diagnose.report import write_json
    from hil.recording import read_recording

    try:
        started = time.perf_counter()
        _check_outputs(args)  # before minutes of fitting, not after
        # refused before being read whole when too long for the memory budget
        recording = read_recording(args.recording, bytes_per_row=DIAGNOSE_BYTES_PER_ROW)
        validate = (read_recording(args.validate, bytes_per_row=DIAGNOSE_BYTES_PER_ROW)
                    if args.validate else None)
        diagnosis = diagnose(recording, validate=validate, cutoff_hz=args.cutoff_hz)
        data = write_json(diagnosis, args.json)
        if args.profile_out:
            write_profile(diagnosis, args.profile_out)
        if args.plots:
            from hil.diagnose.plots import write_plots

            write_plots(diagnosis, args.plots)
    except HilError as exc:
        print(f"gimbal-hil diagnose: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # an output that cannot be written (--json, --plots, --profile-out)
        print(f"gimbal-hil diagnose: error: {exc.filename or ''}: cannot write: "
              f"{exc.strerror or exc}", file=sys.stderr)
        return 2
    causes = data["causes"]
    named = ", ".join(c["name"] for c in causes) if causes else "none"
    print(f"{args.recording}: base fit {data['base']['fit_pct']:.1f} % held out; "
          f"causes: {named} ({time.perf_counter() - started:.1f} s) -> {args.json}")
    return 0


def _check_outputs(args: argparse.Namespace) -> None:
    """Each output can be written where it is asked for: a file's folder is a folder (or can
    be made), a plot folder is not a file.

    Raises
    ------
    InputError
        Naming the option and the path.
    """
    for option, target in (("--json", args.json), ("--profile-out", args.profile_out)):
        if target is None:
            continue
        folder = Path(target).resolve().parent
        blocked = next((p for p in (folder, *folder.parents) if p.exists()), None)
        if blocked is not None and not blocked.is_dir():
            raise InputError(f"{target}: cannot write: {blocked} is a file", source=option)
    if args.plots is not None and Path(args.plots).exists() and not Path(args.plots).is_dir():
        raise InputError(f"{args.plots}: cannot write plots: it is a file", source="--plots")


def main(argv: list[str] | None = None) -> int:
    """``gimbal-hil diagnose`` as a stand-alone program (warnings logged to stderr).

    Parameters
    ----------
    argv : list of str, optional
        The arguments; default ``sys.argv[1:]``.

    Returns
    -------
    int
        The exit code (see :func:`run`).
    """
    parser = argparse.ArgumentParser(prog="gimbal-hil diagnose", description=__doc__)
    add_arguments(parser)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
