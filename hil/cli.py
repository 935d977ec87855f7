"""The ``gimbal-hil`` command: simulate, calibrate, render, diagnose, results, compare,
verify, characterise.

Only argparse and the subcommands' argument definitions load at start (``--help`` stays
fast); a subcommand imports what it needs (numpy, numba, scipy, SQLAlchemy, pytest…) when it
runs.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from hil.characterise.cli import add_arguments as add_characterise_arguments
from hil.compare.cli import add_arguments as add_compare_arguments
from hil.diagnose.cli import add_arguments as add_diagnose_arguments
from hil.drives.kinds import DRIVE_KINDS, KINDS
from hil.errors import HilError, InputError
from hil.store.cli import add_arguments as add_results_arguments

if TYPE_CHECKING:
    from hil.motion import Mode
    from hil.recording import FloatArray

log = logging.getLogger("gimbal-hil")

DESCRIPTION = "gimbal-hil: hardware-in-the-loop calibration of gimbal servo axes."
SIMULATOR_SERIAL = "SIM-0001"  # the plugin's serial for a simulated unit given none

# (name, one line for the command list and the top of its own help)
COMMANDS = (
    ("simulate", "simulate a unit and write its recording (CSV)"),
    ("calibrate", "run the calibration suite (pytest), write the certificate"),
    ("render", "rewrite certificate.html and .pdf of written certificates"),
    ("diagnose", "what does the model get wrong on a recording?"),
    ("results", "the results store: ingest, units, history, trend, spc…"),
    ("compare", "a baseline calibration against a candidate (regression)"),
    ("verify", "check certificates: digest, recordings' SHA-256, outcomes"),
    ("characterise", "a unit type's method-bias map from simulated units"),
)


class HelpFormatter(argparse.HelpFormatter):
    """Every option's default shown after its help, unless the help already says it (a
    default of ``None`` or ``False`` means "not given": its help says what happens then)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        default = action.default
        # identity, not ==: a default of 0 is shown, a flag's False is not
        unset = default is None or default is False or default == argparse.SUPPRESS
        takes_default = bool(action.option_strings) or action.nargs in (argparse.OPTIONAL,
                                                                        argparse.ZERO_OR_MORE)
        if "default" in text or unset or default == [] or not takes_default:
            return text
        return f"{text} (default: %(default)s)"

    def add_argument(self, action: argparse.Action) -> None:
        super().add_argument(action)
        # argparse measures the commands' names at the list's indent, not one level deeper
        # where it prints them: the longest name would wrap its description to a line of
        # its own
        if isinstance(action, argparse._SubParsersAction):
            longest = max((len(name) for name in action.choices), default=0)
            self._action_max_length = max(self._action_max_length, self._current_indent
                                          + self._indent_increment + longest)


def build_parser() -> argparse.ArgumentParser:
    """The whole command line's parser (cheap: no subcommand's dependencies load)."""
    parser = argparse.ArgumentParser(prog="gimbal-hil", description=DESCRIPTION,
                                     formatter_class=HelpFormatter)
    parser.add_argument("-v", "--verbose", action="store_true",
                        help="log at INFO level (default: warnings only)")
    parser.add_argument("--version", action=_Version,
                        help="print gimbal-hil's version and exit")
    commands = parser.add_subparsers(
        dest="subcommand", required=True, title="commands", metavar="COMMAND",
        help="'gimbal-hil COMMAND --help' shows a command's options")
    subs = {name: commands.add_parser(name, help=line, description=line,
                                      formatter_class=HelpFormatter)
            for name, line in COMMANDS}

    sim = subs["simulate"]
    sim.add_argument("--profile", default=None,
                     help="unit profile TOML or built-in name (default: the demo unit)")
    source = sim.add_mutually_exclusive_group(required=True)
    source.add_argument(
        "--command",
        type=Path,
        help="CSV with time_s and one command column "
        "(velocity_cmd_rad_s, torque_cmd_nm or position_cmd_rad); "
        "this or --duration is required",
    )
    source.add_argument("--duration", type=float, metavar="SECONDS",
                        help="seconds of the built-in excitation; this or --command is required")
    sim.add_argument("--out", type=Path, required=True, help="recording to write (.csv[.gz])")
    sim.add_argument("--seed", type=_seed, default=0, help="the simulator's noise seed")

    cal = subs["calibrate"]
    cal.add_argument("--drive", default="sim", choices=DRIVE_KINDS, metavar="KIND",
                     help="the drive to calibrate through: " + ", ".join(DRIVE_KINDS))
    unit = cal.add_mutually_exclusive_group()
    unit.add_argument("--profile", default=None,
                      help="unit profile TOML or built-in name (default: the demo unit)")
    unit.add_argument("--gimbal", default=None, metavar="GIMBAL_PROFILE",
                      help="gimbal profile TOML or built-in name (e.g. demo_gimbal): every "
                           "axis under the one --unit-serial, then one gimbal certificate "
                           "in OUT/SERIAL (default: none, one axis by --profile)")
    cal.add_argument("--unit-serial", default=None, metavar="SERIAL",
                     help="serial number of the unit; required with a real drive ("
                          + ", ".join(k.name for k in KINDS.values() if not k.simulated)
                          + f"); default: {SIMULATOR_SERIAL}, for the simulator and the "
                          "emulators only")
    cal.add_argument("--out", type=Path, default=Path("certificates"),
                     help="folder of the certificates (SERIAL/certificate.json)")
    cal.add_argument("--station", type=Path, default=None,
                     help="station file (TOML; default: none, a simulated station)")
    cal.add_argument("--seed", type=_seed, default=0, help="the simulator's noise seed")
    cal.add_argument("--store", default=None,
                     help="results store URL, or 'off' (default: $GIMBAL_HIL_STORE, the "
                          "station file's store, else OUT/results.sqlite)")
    cal.add_argument("--operator", default=None,
                     help="who runs the calibration (default: $GIMBAL_HIL_OPERATOR, else "
                          "the login name)")
    cal.add_argument("--reference", action="store_true",
                     help="a reference (golden) unit (default: a production unit)")
    cal.add_argument("--gimbal-axis", action="append", default=None, metavar="NAME=PROFILE",
                     help="another axis of this unit's gimbal and its profile, once per axis "
                          "(calibrate --gimbal passes them): with --drive sim the axes are "
                          "simulated together, coupled, the other held by its drive "
                          "(default: none, a one-axis unit)")
    cal.add_argument("--together", action="store_true",
                     help="with --gimbal and --drive sim: both axes at the same time on one "
                          "shared simulated gimbal, each protocol beside the other axis's "
                          "where neither disturbs the other (default: one axis after the "
                          "other)")
    cal.add_argument("--gimbal-link", default=None, metavar="ADDRESS",
                     help="with --drive sim: join the shared simulated gimbal at ADDRESS "
                          "(calibrate --gimbal --together passes it to each axis; default: "
                          "none, the gimbal simulated in this process)")
    cal.add_argument("pytest_args", nargs="*", metavar="PYTEST_ARG",
                     help="extra pytest arguments (after --; default: none)")

    subs["render"].add_argument(
        "certificates", nargs="+", type=Path,
        help="certificate.json files, or the unit directories holding them")

    subs["verify"].add_argument(
        "certificates", nargs="+", type=Path, metavar="CERT_OR_UNIT_DIR",
        help="certificate.json files, or the unit directories holding them; exit 0 when "
             "every one is VERIFIED, 1 when one is not, 2 when one cannot be read")

    add_diagnose_arguments(subs["diagnose"])
    add_results_arguments(subs["results"])
    add_compare_arguments(subs["compare"])
    add_characterise_arguments(subs["characterise"])
    return parser


class _Version(argparse._VersionAction):
    """``--version``: the installed version, read only when asked for."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: object, option_string: str | None = None) -> None:
        from hil import __version__

        print(f"gimbal-hil {__version__}")
        parser.exit()


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    try:
        if args.subcommand == "simulate":
            return _simulate(args)
        if args.subcommand == "calibrate":
            _check_unit_serial(args.drive, args.unit_serial)
            return _calibrate(args)
        if args.subcommand == "render":
            return _render(args)
        if args.subcommand == "results":
            from hil.store.cli import run as run_results

            return run_results(args)
        if args.subcommand == "compare":
            from hil.compare.certificates import same_certificates
            from hil.compare.cli import run as run_compare

            for line in same_certificates(args.baseline, args.candidate):
                print(f"gimbal-hil compare: warning: {line}", file=sys.stderr)
            return run_compare(args)
        if args.subcommand == "verify":
            return _verify(args)
        if args.subcommand == "characterise":
            from hil.characterise.cli import run as run_characterise

            return run_characterise(args)
        from hil.diagnose.cli import run as run_diagnose

        return run_diagnose(args)
    except HilError as exc:
        print(f"gimbal-hil: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader went away (`| head`): what it read was complete
        with contextlib.suppress(OSError, ValueError):  # no error flushing at exit
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # as a shell reports a process ended by SIGPIPE
    except Exception as exc:  # a bug: one line for the operator, the traceback with -v
        if args.verbose:
            raise
        print(f"gimbal-hil: internal error: {type(exc).__name__}: {exc} (a bug in "
              f"gimbal-hil: run it again with -v for the traceback and report it)",
              file=sys.stderr)
        return INTERNAL_ERROR


def _check_unit_serial(drive: str, serial: str | None) -> None:
    """A real unit needs its serial (the default one is the simulator's); a blank one is
    never a serial. Checked before pytest starts."""
    if serial is not None and not serial.strip():
        raise InputError("a unit serial cannot be blank", source="--unit-serial")
    if serial is None and not KINDS[drive].simulated:
        raise InputError(f"--drive {drive} calibrates a real unit: give its --unit-serial "
                         f"SERIAL (the default {SIMULATOR_SERIAL} is for the simulator only)")


#: exit status of a bug (an exception gimbal-hil did not raise on purpose)
INTERNAL_ERROR = 3

#: the longest built-in excitation `simulate` plans: two hours at the demo's 4 kHz keep a
#: run's arrays (~30 columns of float64 and the CSV text) near 2 GB
MAX_SIMULATED_S = 7200.0


def _seed(text: str) -> int:
    """A noise seed: a whole number from 0 (numpy's generators take no negative seed)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {value}")
    return value


def _simulate(args: argparse.Namespace) -> int:
    from hil.drives.sim import SimDrive
    from hil.motion import Excitation, Mode
    from hil.profile import load_profile
    from hil.recording import write_recording
    from plant_sim.excitations import identification_sequence

    profile = load_profile(args.profile)
    if profile.plant is None:
        raise InputError("profile has no [plant] table to simulate", source=profile.source)
    fs_hz = profile.sample_rate_hz
    if args.duration is not None and not (
            math.isfinite(args.duration) and args.duration <= MAX_SIMULATED_S):
        raise InputError(f"must be a number of seconds from 8 to {MAX_SIMULATED_S:g} (a "
                         f"recording's arrays are planned whole), got {args.duration:g}",
                         source="--duration")
    if args.command is not None:
        mode, command = _command_from_csv(args.command, fs_hz)
        name = args.command.name
    else:
        limits = profile.limits
        travel = min(-limits.travel_min_rad, limits.travel_max_rad)
        try:
            command = identification_sequence(
                args.duration, fs_hz, travel_rad=travel, max_velocity_rad_s=limits.velocity_rad_s
            )
        except ValueError as exc:  # too short for the built-in excitation
            raise InputError(str(exc), source="--duration") from None
        mode, name = Mode.VELOCITY, f"builtin_{args.duration:g}s"
    drive = SimDrive(profile.plant, firmware=profile.firmware, limits=profile.limits,
                     fs_hz=fs_hz, seed=args.seed)
    with drive:
        drive.enable()
        recording = drive.run(Excitation(name=name, mode=mode, command=command, fs_hz=fs_hz))
    sha = write_recording(recording, args.out)
    print(f"{args.out}: {len(recording)} samples, {recording.duration_s:.2f} s, sha256 {sha}")
    return 0


def _command_from_csv(path: Path, fs_hz: float) -> tuple[Mode, FloatArray]:
    """Read a command file and resample it (linear) onto the drive's sample grid."""
    import numpy as np

    from hil.motion import MODE_OF_COLUMN
    from hil.recording import read_command_csv

    columns = read_command_csv(path, allowed=tuple(MODE_OF_COLUMN))
    ((name, values),) = ((k, v) for k, v in columns.items() if k != "time_s")
    time_s = columns["time_s"]
    grid = time_s[0] + np.arange(int((time_s[-1] - time_s[0]) * fs_hz) + 1) / fs_hz
    return MODE_OF_COLUMN[name], np.interp(grid, time_s, values)


def _calibrate(args: argparse.Namespace) -> int:
    if args.gimbal is not None:
        return _calibrate_gimbal(args)
    _check_unit_folder(args.out, args.unit_serial or SIMULATOR_SERIAL)
    import pytest

    options = ["--drive", args.drive, "--out", str(args.out), "--seed", str(args.seed)]
    if args.profile:
        options += ["--profile", str(args.profile)]
    if args.unit_serial:
        options += ["--unit-serial", args.unit_serial]
    if args.station:
        options += ["--station", str(args.station)]
    options += ["--store", args.store] if args.store else []
    options += ["--operator", args.operator] if args.operator else []
    options += ["--reference"] if args.reference else []
    for sibling in args.gimbal_axis or []:
        options += ["--gimbal-axis", sibling]
    options += ["--gimbal-link", args.gimbal_link] if args.gimbal_link else []
    return int(pytest.main([*suite_arguments(), *options, *args.pytest_args]))


def _calibrate_gimbal(args: argparse.Namespace) -> int:
    from hil.drives.station import load_station_identity
    from hil.gimbal.profile import load_gimbal_profile
    from hil.gimbal.run import calibrate_gimbal
    from hil.store.engine import resolve_store_url

    gimbal = load_gimbal_profile(args.gimbal)
    serial = args.unit_serial or SIMULATOR_SERIAL
    station = load_station_identity(args.station) if args.station else None
    store = "off" if args.store == "off" else resolve_store_url(
        args.store, out_dir=args.out, station_store=station.store if station else None)
    options = ["--drive", args.drive, "--seed", str(args.seed)]
    options += ["--station", str(args.station)] if args.station else []
    options += ["--operator", args.operator] if args.operator else []
    options += ["--reference"] if args.reference else []
    options += ["--", *args.pytest_args] if args.pytest_args else []
    return calibrate_gimbal(gimbal, serial=serial, out=args.out, store_url=store,
                            options=options, together=args.together)


def _check_unit_folder(out: Path, serial: str) -> None:
    """A unit folder another calibration is writing is refused here, in one line (exit 2);
    the calibration then holds the folder's lock for its whole run (a usage error if it
    lost a race for it, before any motion)."""
    import re

    from hil.calibration import SERIAL_PATTERN, UnitLock

    # a bad serial is refused by the run itself; a folder no run has made holds no writer
    # (and a run refused before motion leaves nothing behind)
    if re.fullmatch(SERIAL_PATTERN, serial) and (out / serial).is_dir():
        UnitLock.acquire(out / serial).release()


def suite_arguments() -> list[str]:
    """pytest's arguments for the installed suite, whatever folder the operator stands in:
    no configuration file, ``conftest.py`` or cache of the current folder is read or written
    (a repository's own tests, say, and the test extras they need)."""
    from hil.plugin import protocols_dir

    suite = str(protocols_dir())
    # the command has imported hil already: pytest cannot rewrite the asserts of the
    # package its plugin comes from (the protocols' asserts carry their own messages)
    # the test extras' plugins, where installed, have nothing to do in a calibration
    # (hypothesis alone imports for a second at the run's end); pytest's unraisable-
    # exception plugin collects the garbage five times over at the end (0.6 s of a 7 s
    # calibration) to turn a ``__del__`` error into a warning: Python prints it anyway
    return [suite, "-c", os.devnull, "--rootdir", suite, "--confcutdir", suite,
            "-p", "no:cacheprovider", "-p", "no:hypothesispytest", "-p", "no:benchmark",
            "-p", "no:unraisableexception", "-q", "-W", "ignore::pytest.PytestAssertRewriteWarning"]


def _render(args: argparse.Namespace) -> int:
    from hil.report.documents import certificate_file, write_documents

    paths = [certificate_file(target) for target in args.certificates]
    failed = 0
    for path in paths:
        problems = write_documents(path)
        for problem in problems:
            print(f"{path.parent}: {problem}", file=sys.stderr)
        failed += bool(problems)
        if not problems:
            print(f"{path.parent}: certificate.html, certificate.pdf")
    return 1 if failed else 0


def _verify(args: argparse.Namespace) -> int:
    """Each certificate: one line per problem, then VERIFIED or NOT VERIFIED."""
    from hil.certificate.integrity import (
        NO_DIGEST,
        certificate_path,
        read_document,
        verify_document,
    )
    from hil.gimbal.verify import gimbal_certificate_path, verify_gimbal

    worst = 0
    for target in args.certificates:
        gimbal = gimbal_certificate_path(target)
        if gimbal is not None:  # a gimbal: each axis's certificate, as recorded
            try:
                problems, verified = verify_gimbal(gimbal)
            except InputError as exc:
                print(f"gimbal-hil: error: {exc}", file=sys.stderr)
                worst = 2
                continue
            for line in problems:
                print(f"{gimbal}: {line}")
            print(f"{gimbal}: {'VERIFIED' if verified else 'NOT VERIFIED'}")
            worst = max(worst, 0 if verified else 1)
            continue
        path = certificate_path(target)
        try:
            document = read_document(path)
            schema = str(document.get("schema", ""))
            if not schema.startswith("gimbal-hil/certificate/"):
                raise InputError(f"not a gimbal-hil certificate (schema {schema!r})",
                                 source=str(path))
        except InputError as exc:
            print(f"gimbal-hil: error: {exc}", file=sys.stderr)
            worst = 2
            continue
        found = verify_document(document, path=path, unit_dir=path.parent)
        for line in (*([] if found.digest else [NO_DIGEST]), *found.problems):
            print(f"{path}: {line}")
        print(f"{path}: {'VERIFIED' if found.verified else 'NOT VERIFIED'}")
        worst = max(worst, 0 if found.verified else 1)
    return worst


if __name__ == "__main__":
    sys.exit(main())
