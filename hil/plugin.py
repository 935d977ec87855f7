"""The ``pytest11`` entry point: inert until asked for.

It only declares the command-line options. The calibration machinery (fixtures, protocol
ordering, the certificate hook, :mod:`hil.calibration_session`) is registered when the run
asks for it: a ``--drive``, ``--profile``, ``--unit-serial`` or ``--station`` option, or a
collection that includes the protocol suite. Another project's test run sees nothing else:
no profile is read and no fixture wraps its tests.

A unit profile that does not load stops the run there, before collection and any motion,
with one line naming file, table and key (pytest's usage error, exit code 4).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from hil.drives.kinds import DRIVE_KINDS

PLUGIN_NAME = "gimbal-hil-calibration"
CALIBRATION_OPTIONS = ("drive", "profile", "unit_serial", "station")


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("gimbal-hil", "gimbal-hil calibration")
    group.addoption(
        "--drive",
        default=None,
        choices=DRIVE_KINDS,
        help="drive backend for calibration protocols (default: sim)",
    )
    group.addoption(
        "--profile",
        default=None,
        help="unit profile TOML, or a built-in profile name (default: demo unit)",
    )
    group.addoption(
        "--unit-serial",
        default=None,
        help="serial number of the unit under calibration (default SIM-0001 for sim)",
    )
    group.addoption(
        "--out",
        default="certificates",
        help="directory for certificates and raw recordings (default: certificates)",
    )
    group.addoption(
        "--station",
        default=None,
        type=Path,
        help="station TOML for real drives (interface, node id, EDS, register map)",
    )
    group.addoption("--seed", default=0, type=int, help="simulator seed (sim and emulators)")
    group.addoption(
        "--sim-pace",
        default=None,
        type=float,
        metavar="MULTIPLE",
        help="--drive sim keeps its motion to the wall clock at this multiple of real time "
        "(1: as a drive does; a rehearsal of a station's timing and stops); default: as "
        "fast as it computes",
    )
    group.addoption(
        "--gimbal-axis",
        action="append",
        default=[],
        metavar="NAME=PROFILE",
        help="another axis of this unit's gimbal and its profile (calibrate --gimbal passes "
        "each); with --drive sim it is simulated with this axis, coupled, held by its own "
        "drive (default: none, a one-axis unit)",
    )
    group.addoption(
        "--gimbal-link",
        default=None,
        metavar="ADDRESS",
        help="with --drive sim: join the shared simulated gimbal at ADDRESS instead of "
        "simulating it here (calibrate --gimbal --together passes it; its key in "
        "$GIMBAL_HIL_LINK_KEY); default: none",
    )
    group.addoption(
        "--method-bias",
        default=None,
        help="method-bias map (TOML) the results are corrected with; 'off' for none "
        "(default: the one shipped, measured by benchmarks/bench_coverage.py)",
    )
    group.addoption(
        "--no-documents",
        action="store_true",
        help="write certificate.json/.txt only, not the HTML and PDF (population benchmarks)",
    )
    group.addoption(
        "--store",
        default=None,
        help="results store URL (postgresql://…, sqlite:///FILE) or 'off' (default: "
        "$GIMBAL_HIL_STORE, the station file's store, else OUT/results.sqlite)",
    )
    group.addoption("--operator", default=None, help="who runs the calibration (default: "
                    "$GIMBAL_HIL_OPERATOR, else the login name)")
    group.addoption("--reference", action="store_true", default=False,
                    help="the unit is a reference (golden) unit: kept out of fleet statistics")


def pytest_configure(config: pytest.Config) -> None:
    if not calibration_requested(config):
        return
    from hil import calibration_session

    calibration_session.start(config)
    config.pluginmanager.register(calibration_session, PLUGIN_NAME)


def calibration_requested(config: pytest.Config) -> bool:
    """A calibration option was given, or the paths to collect include the protocol suite."""
    if any(config.getoption(name, default=None) is not None for name in CALIBRATION_OPTIONS):
        return True
    suite = protocols_dir()
    return any(_overlaps(path, suite) for path in _collected_paths(config))


def protocols_dir() -> Path:
    spec = importlib.util.find_spec("gimbal_hil_protocols")
    if spec is None or spec.origin is None:
        raise pytest.UsageError("gimbal-hil's protocol suite is not installed (pip install -e .)")
    return Path(spec.origin).resolve().parent


def _collected_paths(config: pytest.Config) -> list[Path]:
    paths = []
    for arg in config.args:
        target = arg.split("::", 1)[0]
        if config.option.pyargs and not Path(target).exists():
            try:
                spec = importlib.util.find_spec(target)
            except (ImportError, ValueError):
                spec = None
            if spec is None or spec.origin is None:
                continue
            origin = Path(spec.origin)
            target = str(origin.parent if origin.name == "__init__.py" else origin)
        paths.append(Path(config.invocation_params.dir, target).resolve())
    return paths


def _overlaps(path: Path, suite: Path) -> bool:
    return path == suite or suite in path.parents or path in suite.parents
