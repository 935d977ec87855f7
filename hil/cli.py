"""The ``gimbal-hil`` command: simulate, calibrate, diagnose, compare."""

from __future__ import annotations

import argparse
import logging
import os
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from hil.compare.cli import add_arguments as add_compare_arguments
from hil.compare.cli import run as run_compare
from hil.diagnose.cli import add_arguments as add_diagnose_arguments
from hil.diagnose.cli import run as run_diagnose
from hil.drives.kinds import DRIVE_KINDS
from hil.errors import HilError, InputError
from hil.motion import MODE_OF_COLUMN, Excitation, Mode
from hil.profile import load_profile
from hil.recording import FloatArray, read_command_csv, write_recording
from hil.store.cli import add_arguments as add_results_arguments
from hil.store.cli import run as run_results

log = logging.getLogger("gimbal-hil")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="gimbal-hil", description=__doc__)
    parser.add_argument("-v", "--verbose", action="store_true", help="log at INFO level")
    commands = parser.add_subparsers(dest="subcommand", required=True)

    sim = commands.add_parser("simulate", help="simulate a unit and write a recording")
    sim.add_argument("--profile", default=None, help="unit profile TOML or built-in name")
    source = sim.add_mutually_exclusive_group(required=True)
    source.add_argument(
        "--command",
        type=Path,
        help="CSV with time_s and one command column "
        "(velocity_cmd_rad_s, torque_cmd_nm or position_cmd_rad)",
    )
    source.add_argument("--duration", type=float, help="seconds of the built-in excitation")
    sim.add_argument("--out", type=Path, required=True, help="recording to write (.csv[.gz])")
    sim.add_argument("--seed", type=int, default=0)

    cal = commands.add_parser("calibrate", help="run the calibration suite through pytest")
    cal.add_argument("--drive", default="sim", choices=DRIVE_KINDS)
    cal.add_argument("--profile", default=None)
    cal.add_argument("--unit-serial", default=None)
    cal.add_argument("--out", type=Path, default=Path("certificates"))
    cal.add_argument("--station", type=Path, default=None)
    cal.add_argument("--seed", type=int, default=0)
    cal.add_argument("--store", default=None, help="results store URL, or 'off'")
    cal.add_argument("--operator", default=None)
    cal.add_argument("--reference", action="store_true", help="a reference (golden) unit")
    cal.add_argument("pytest_args", nargs="*", help="extra pytest arguments (after --)")

    render = commands.add_parser(
        "render", help="(re)write certificate.html and certificate.pdf of written certificates")
    render.add_argument("certificates", nargs="+", type=Path,
                        help="certificate.json files, or the unit directories holding them")

    diag = commands.add_parser("diagnose", help="what does the model get wrong on a recording?")
    add_diagnose_arguments(diag)
    add_results_arguments(commands.add_parser("results", help="the results store"))

    comp = commands.add_parser("compare", help="baseline calibration against a candidate")
    add_compare_arguments(comp)

    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    try:
        if args.subcommand == "simulate":
            return _simulate(args)
        if args.subcommand == "calibrate":
            return _calibrate(args)
        if args.subcommand == "render":
            return _render(args)
        if args.subcommand == "results":
            return run_results(args)
        if args.subcommand == "compare":
            return run_compare(args)
        return run_diagnose(args)
    except HilError as exc:
        print(f"gimbal-hil: error: {exc}", file=sys.stderr)
        return 2


def _simulate(args: argparse.Namespace) -> int:
    from hil.drives.sim import SimDrive
    from plant_sim.excitations import identification_sequence

    profile = load_profile(args.profile)
    if profile.plant is None:
        raise InputError("profile has no [plant] table to simulate", source=profile.source)
    fs_hz = profile.sample_rate_hz
    if args.command is not None:
        mode, command = _command_from_csv(args.command, fs_hz)
        name = args.command.name
    else:
        limits = profile.limits
        travel = min(-limits.travel_min_rad, limits.travel_max_rad)
        command = identification_sequence(
            args.duration, fs_hz, travel_rad=travel, max_velocity_rad_s=limits.velocity_rad_s
        )
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
    columns = read_command_csv(path, allowed=tuple(MODE_OF_COLUMN))
    ((name, values),) = ((k, v) for k, v in columns.items() if k != "time_s")
    time_s = columns["time_s"]
    grid = time_s[0] + np.arange(int((time_s[-1] - time_s[0]) * fs_hz) + 1) / fs_hz
    return MODE_OF_COLUMN[name], np.interp(grid, time_s, values)


def _calibrate(args: argparse.Namespace) -> int:
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
    return int(pytest.main([*suite_arguments(), *options, *args.pytest_args]))


def suite_arguments() -> list[str]:
    """pytest's arguments for the installed suite, whatever folder the operator stands in:
    no configuration file, ``conftest.py`` or cache of the current folder is read or written
    (a repository's own tests, say, and the test extras they need)."""
    from hil.plugin import protocols_dir

    suite = str(protocols_dir())
    # the command has imported hil already: pytest cannot rewrite the asserts of the
    # package its plugin comes from (the protocols' asserts carry their own messages)
    return [suite, "-c", os.devnull, "--rootdir", suite, "--confcutdir", suite,
            "-p", "no:cacheprovider", "-q", "-W", "ignore::pytest.PytestAssertRewriteWarning"]


def _render(args: argparse.Namespace) -> int:
    from hil.report import certificate_file, write_documents

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


if __name__ == "__main__":
    sys.exit(main())
