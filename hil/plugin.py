"""pytest plugin: options, the ``drive``/``calibration`` fixtures and the certificate hook.

Thin on purpose: fixtures look things up, state lives in ``config.stash``.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Generator, Iterator
from pathlib import Path

import pytest

from hil.calibration import CalibrationRun
from hil.certificate import write_certificate
from hil.drives import DRIVE_KINDS, open_drive
from hil.drives.base import Drive
from hil.errors import HilError
from hil.measurement import Outcome
from hil.profile import UnitProfile, load_profile

log = logging.getLogger(__name__)

RUN_KEY = pytest.StashKey[CalibrationRun]()
PROFILE_KEY = pytest.StashKey[UnitProfile]()
CERTIFICATE_KEY = pytest.StashKey[Path]()
PROTOCOL_MARK = "protocol"


SIMULATED = ("sim", "canopen-emulator", "modbus-emulator")  # need no --unit-serial


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("gimbal-hil", "gimbal-hil calibration")
    group.addoption(
        "--drive",
        default="sim",
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


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", f"{PROTOCOL_MARK}: a calibration protocol")
    kind = config.getoption("--drive", default="sim")
    if config.getoption("--unit-serial", default=None) is None and kind not in SIMULATED:
        raise pytest.UsageError(f"--drive {kind} (a real unit) needs --unit-serial SERIAL")


def _load_profile(config: pytest.Config) -> UnitProfile:
    """The unit profile named by ``--profile``, read once per session."""
    if PROFILE_KEY not in config.stash:
        config.stash[PROFILE_KEY] = load_profile(config.getoption("--profile"))
    return config.stash[PROFILE_KEY]


@pytest.fixture(scope="session")
def profile(pytestconfig: pytest.Config) -> UnitProfile:
    """The unit profile named by ``--profile`` (default: the built-in demo unit)."""
    try:
        return _load_profile(pytestconfig)
    except HilError as exc:
        raise pytest.UsageError(str(exc)) from exc


@pytest.fixture(scope="session")
def calibration(pytestconfig: pytest.Config, profile: UnitProfile) -> CalibrationRun:
    """The calibration run collecting recordings and judged measurements for the certificate."""
    if RUN_KEY not in pytestconfig.stash:
        kind = pytestconfig.getoption("--drive")
        serial = pytestconfig.getoption("--unit-serial")
        if serial is None:  # a simulated unit (pytest_configure refused a real one)
            serial = "SIM-0001"
        pytestconfig.stash[RUN_KEY] = CalibrationRun(
            profile=profile,
            unit_serial=serial,
            out_dir=Path(pytestconfig.getoption("--out")),
            drive_kind=kind,
        )
    return pytestconfig.stash[RUN_KEY]


@pytest.fixture(scope="session")
def drive_connection(
    pytestconfig: pytest.Config, profile: UnitProfile, calibration: CalibrationRun
) -> Iterator[Drive]:
    """The open drive for the whole session; closed (and disabled) at the end."""
    with open_drive(
        pytestconfig.getoption("--drive"),
        profile=profile,
        unit_serial=calibration.unit_serial,
        station=pytestconfig.getoption("--station"),
        seed=pytestconfig.getoption("--seed"),
    ) as drive:
        calibration.drive_info = drive.info
        yield drive


@pytest.fixture(scope="module")
def drive(request: pytest.FixtureRequest, drive_connection: Drive) -> Iterator[Drive]:
    """The drive, enabled for one protocol module; afterwards quick-stopped if anything in
    the module failed, and always disabled."""
    failures_before = request.session.testsfailed
    drive_connection.enable()
    try:
        yield drive_connection
    finally:
        try:
            if request.session.testsfailed != failures_before:
                drive_connection.quick_stop()
        finally:
            drive_connection.disable()


@pytest.fixture(autouse=True)
def _allure_measurements(request: pytest.FixtureRequest) -> Iterator[None]:
    """With allure-pytest active, attach each protocol test's judged measurements."""
    run = request.config.stash.get(RUN_KEY, None)
    before = len(run.measurements) if run else 0
    yield
    run = request.config.stash.get(RUN_KEY, None)
    if run is None or not request.config.pluginmanager.hasplugin("allure_pytest"):
        return
    import allure

    for measurement in run.measurements[before:]:
        allure.attach(
            json.dumps(measurement.as_dict(), indent=2),
            name=measurement.spec.name,
            attachment_type=allure.attachment_type.JSON,
        )


def _protocol_name(item: pytest.Item) -> str | None:
    mark = item.get_closest_marker(PROTOCOL_MARK)
    if mark is None:
        return None
    return str(mark.args[0]) if mark.args else item.name


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Run protocols in the order of the profile's ``[protocols.*]`` tables (later protocols
    may use earlier results, e.g. J for an acceleration correction); others keep their place."""
    try:
        order = list(_load_profile(config).protocols)
    except HilError:
        return  # the profile fixture reports the problem
    slots = [i for i, item in enumerate(items) if _protocol_name(item) is not None]

    def rank(item: pytest.Item) -> int:
        name = _protocol_name(item)
        return order.index(name) if name in order else len(order)

    ordered = sorted((items[i] for i in slots), key=rank)
    for slot, item in zip(slots, ordered, strict=True):
        items[slot] = item


def pytest_runtest_setup(item: pytest.Item) -> None:
    """A protocol the unit's profile does not configure is skipped, with the reason."""
    name = _protocol_name(item)
    if name is None:
        return
    try:
        configured = name in _load_profile(item.config).protocols
    except HilError:
        return  # the profile fixture reports the problem
    if not configured:
        pytest.skip(f"the unit profile has no [protocols.{name}] table: not calibrated here")


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(
    item: pytest.Item, call: pytest.CallInfo[None]
) -> Generator[None, pytest.TestReport, pytest.TestReport]:
    report: pytest.TestReport = yield
    name = _protocol_name(item)
    run = item.config.stash.get(RUN_KEY, None)
    if name is None or run is None:
        return report
    if report.failed:
        outcome = Outcome.FAIL if report.when == "call" else Outcome.ERROR
        if call.excinfo is not None and not isinstance(call.excinfo.value, AssertionError):
            outcome = Outcome.ERROR
        message = call.excinfo.exconly() if call.excinfo else report.longreprtext[:200]
        run.report_protocol(name, outcome, f"{item.name}: {message[:300]}")
    elif report.skipped:
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else "skipped"
        run.report_skip(name, f"{item.name}: {reason}")
    elif report.when == "call" and report.passed:
        run.report_protocol(name, Outcome.PASS)
    return report


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    run = session.config.stash.get(RUN_KEY, None)
    if run is None or not run.active:
        return
    aborted = exitstatus == pytest.ExitCode.INTERRUPTED or session.shouldstop is not False
    session.config.stash[CERTIFICATE_KEY] = write_certificate(run, aborted=bool(aborted))


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    config = terminalreporter.config
    path = config.stash.get(CERTIFICATE_KEY, None)
    run = config.stash.get(RUN_KEY, None)
    if path is None or run is None:
        return
    terminalreporter.section("gimbal-hil calibration")
    for m in run.measurements:
        e = m.estimate
        terminalreporter.write_line(
            f"{m.spec.name:<26}{e.value:>12.6g} ± {e.expanded_uncertainty:<9.2g}"
            f"{m.spec.unit:<11}{m.outcome.value}"
        )
    outcome = json.loads(path.read_text(encoding="utf-8"))["outcome"]
    terminalreporter.write_line(f"certificate: {path}")
    terminalreporter.write_line(f"unit {run.unit_serial}: {outcome}")
