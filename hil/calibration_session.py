"""A calibration session under pytest: the ``profile``, ``calibration`` and ``drive``
fixtures, protocol ordering and outcomes, and the certificate hook.

Registered by :mod:`hil.plugin` only when a run asks for calibration. Thin on purpose:
fixtures look things up, state lives in ``config.stash``.
"""

from __future__ import annotations

import getpass
import json
import logging
import os
import re
import signal
import socket
import threading
import time
from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import FrameType

import pytest

from hil.beside import ALONE, Planned
from hil.budget import (
    CALIBRATE_BYTES_PER_SAMPLE,
    StorageError,
    address_space_bounded,
    check_disk,
    check_memory,
    storage_error,
)
from hil.calibration import (
    SERIAL_PATTERN,
    CalibrationRun,
    UnitLock,
    certificate_axis,
    check_serial,
)
from hil.certificate import write_certificate
from hil.certificate.build import result_record
from hil.certificate.model import read_certificate
from hil.drives.base import Capability, Drive, DriveInfo
from hil.drives.connect import open_drive
from hil.drives.kinds import drive_kind as kind_named
from hil.drives.station import StationIdentity, load_station_identity
from hil.errors import HilError, InputError
from hil.gum import rounded_pair
from hil.measurement import MethodBiasMap, Outcome, load_method_bias
from hil.motion import Mode
from hil.profile import UnitProfile, load_profile
from hil.report.console import outcome_banner, protocol_start
from hil.report.junit import PYTEST_DEFAULT_SUITE_NAME, measurement_properties, suite_name
from hil.report.junit import suite_properties as junit_suite_properties
from hil.stop_request import StopRequest
from hil.store.engine import resolve_store_url
from hil.store.record import record_run
from hil.suite.catalogue import CATALOGUE, PROTOCOL_OF, check_profile
from hil.suite.plan import check_protocol_settings, planned_motion_s

log = logging.getLogger(__name__)

RUN_KEY = pytest.StashKey[CalibrationRun]()
PROFILE_KEY = pytest.StashKey[UnitProfile]()
CERTIFICATE_KEY = pytest.StashKey[Path]()
DOCUMENTS_KEY = pytest.StashKey[list[str]]()
STORE_MESSAGE_KEY = pytest.StashKey[str]()
STATION_KEY = pytest.StashKey[StationIdentity]()
GIMBAL_AXES_KEY = pytest.StashKey[dict[str, UnitProfile]]()
REFUSALS_KEY = pytest.StashKey[list[HilError]]()
STORAGE_FAILURE_KEY = pytest.StashKey[str]()  # the certificate could not be written
STOP_KEY = pytest.StashKey[StopRequest]()  # a stop signal, kept should its interrupt be lost
PROTOCOL_MARK = "protocol"


@dataclass(slots=True)
class _Console:
    """What the operator's console has shown: the protocol running, since when."""

    current: str | None = None
    started_s: float | None = None


CONSOLE_KEY = pytest.StashKey[_Console]()


def start(config: pytest.Config) -> None:
    """Check the calibration options and read the unit profile, before collection: a real
    unit without a serial, or a profile that does not load (an unknown table, a protocol
    setting its protocol refuses), is one usage error (exit 4)."""
    config.addinivalue_line("markers", f"{PROTOCOL_MARK}: a calibration protocol")
    config.stash[CONSOLE_KEY] = _Console()
    _stop_on_signals(config)
    kind = drive_kind(config)
    if config.getoption("--unit-serial") is None and not kind_named(kind).simulated:
        raise pytest.UsageError(f"--drive {kind} (a real unit) needs --unit-serial SERIAL")
    pace = config.getoption("--sim-pace")
    if pace is not None and not (pace > 0 and kind == "sim"):
        raise pytest.UsageError(f"--sim-pace {pace}: a positive multiple of real time, "
                                "for --drive sim (a field bus keeps its own pace)")
    try:
        profile = config.stash[PROFILE_KEY] = load_profile(config.getoption("--profile"))
        # every table known and every protocol's settings read, before any motion
        check_profile(profile)
        with address_space_bounded("building the profile's excitations",
                                   source=profile.source):  # 200,000 Stribeck speeds: 23 GB
            check_protocol_settings(profile, _planning_info(profile))
        _check_resources(config, profile)
        _check_run_options(config, profile, kind)
        config.stash[GIMBAL_AXES_KEY] = _gimbal_axes(config.getoption("--gimbal-axis"),
                                                     profile=profile)
        station = config.getoption("--station")
        config.stash[STATION_KEY] = (
            load_station_identity(station) if station is not None else StationIdentity()
        )
        if config.getoption("--store") != "off":  # a bad URL stops here, before any motion
            resolve_store_url(config.getoption("--store"), out_dir=Path(),
                              station_store=config.stash[STATION_KEY].store)
        _lock_unit_folder(config, axis=profile.axis)
    except HilError as exc:
        raise pytest.UsageError(str(exc)) from None


def _gimbal_axes(items: list[str], *, profile: UnitProfile) -> dict[str, UnitProfile]:
    """The gimbal's other axes (``--gimbal-axis NAME=PROFILE``), each profile loaded.

    Raises
    ------
    InputError
        An item without ``=``, the axis under test or an axis named twice; a profile that
        calibrates another axis than its name.
    """
    axes: dict[str, UnitProfile] = {}
    for item in items:
        name, sep, path = item.partition("=")
        if not sep or not name or not path:
            raise InputError(f"--gimbal-axis {item!r}: NAME=PROFILE expected")
        if name == profile.axis or name in axes:
            raise InputError(f"--gimbal-axis {item!r}: the '{name}' axis is named twice")
        sibling = load_profile(path)
        if sibling.axis != name:
            raise InputError(f"--gimbal-axis {item!r}: the profile calibrates the "
                             f"'{sibling.axis}' axis", source=sibling.source)
        axes[name] = sibling
    return axes


def _check_run_options(config: pytest.Config, profile: UnitProfile, kind: str) -> None:
    """What the run would otherwise find per protocol, once per test: a unit serial it
    cannot file, a simulated drive without a plant to simulate, a method-bias map that
    does not load.

    Raises
    ------
    InputError
        Naming the option or the file.
    """
    serial = config.getoption("--unit-serial")
    if serial is not None:
        check_serial(serial)
    if kind_named(kind).simulated and profile.plant is None:
        raise InputError(f"--drive {kind} simulates the unit from the profile's [plant] "
                         "table, and it has none", source=profile.source)
    _method_bias(config.getoption("--method-bias"), profile)


def _check_resources(config: pytest.Config, profile: UnitProfile) -> None:
    """Memory and disk before the first motion, from the planned samples: the largest
    protocol's samples within the memory budget, every recording and the documents within
    the free space of --out (hil/budget.py states the sizes and margins).

    Raises
    ------
    InputError
        One line naming the budget or the folder, what is there and what is needed.
    """
    info = _planning_info(profile)
    samples = {name: seconds * info.max_sample_rate_hz
               for name, seconds in planned_motion_s(profile, info).items()}
    if not samples:
        return
    largest = max(samples, key=lambda name: samples[name])
    check_memory(samples[largest] * CALIBRATE_BYTES_PER_SAMPLE,
                 f"protocol {largest} ({samples[largest]:,.0f} samples at "
                 f"{info.max_sample_rate_hz:g} Hz, {CALIBRATE_BYTES_PER_SAMPLE:,} B each)",
                 source=profile.source)
    if not config.option.collectonly:
        check_disk(Path(config.getoption("--out")), samples=sum(samples.values()))


def _lock_unit_folder(config: pytest.Config, *, axis: str) -> None:
    """One writer per unit folder, from before the first write to the end of the run: a
    second calibration of the serial into the same --out is refused here, before motion,
    and so is one of another axis than the folder's certificate (it would file the other
    axis's calibration as an earlier one of this axis)."""
    serial = config.getoption("--unit-serial")
    serial = "SIM-0001" if serial is None else serial  # as the calibration fixture has it
    if config.option.collectonly or not re.fullmatch(SERIAL_PATTERN, serial):
        return  # nothing written; a bad serial is refused where the run is made
    lock = UnitLock.acquire(Path(config.getoption("--out")) / serial)
    config.add_cleanup(lock.release)
    held = certificate_axis(lock.path.parent / "certificate.json")
    if held is not None and held != axis:
        lock.release()
        raise InputError(
            f"{lock.path.parent} holds the {held} axis's calibration of {serial}; this "
            f"profile calibrates its {axis} axis: calibrate each axis of a gimbal into its "
            f"own --out folder (e.g. --out {lock.path.parent.parent / axis})")


#: each a stop: quick stop, disable, an aborted certificate
STOP_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")


def _stop_on_signals(config: pytest.Config) -> None:
    """SIGINT, SIGTERM and SIGHUP raise ``KeyboardInterrupt``: the run stops on pytest's
    interrupted path (the drive quick-stopped and disabled, an aborted certificate). A
    repeated signal while stopping is ignored (Ctrl-C under ``--gimbal`` reaches the axis
    twice: from the terminal and passed on). SIGINT is honoured even when the process
    started with it ignored (a background job of a script, an axis of a gimbal started
    so): a stop request always stops the motion. The request is kept too (``STOP_KEY``):
    an interrupt raised inside a finaliser is dropped by Python, the request is not. The
    previous handlers return at the end."""
    request = config.stash[STOP_KEY] = StopRequest()
    if threading.current_thread() is not threading.main_thread():
        return  # signal handlers can only be set from the main thread

    def interrupt(signum: int, _frame: FrameType | None) -> None:
        name = signal.Signals(signum).name
        if request.signal_name is not None:
            log.warning("%s while stopping after %s: ignored", name, request.signal_name)
            return
        request.ask(name)
        raise KeyboardInterrupt(f"{name}: the calibration stops")

    for name in STOP_SIGNALS:
        number = getattr(signal, name, None)
        if number is None:  # no SIGHUP on Windows
            continue
        config.add_cleanup(_restorer(number, signal.signal(number, interrupt)))


def _restorer(number: int, previous: signal.Handlers | Callable[[int, FrameType | None], object]
              | int | None) -> Callable[[], None]:
    """Puts back the handler a signal had before the calibration."""
    def restore() -> None:
        signal.signal(number, previous)
    return restore


def drive_kind(config: pytest.Config) -> str:
    return str(config.getoption("--drive") or "sim")


@pytest.fixture(scope="session")
def profile(pytestconfig: pytest.Config) -> UnitProfile:
    """The unit profile named by ``--profile`` (default: the built-in demo unit)."""
    return pytestconfig.stash[PROFILE_KEY]


@pytest.fixture(scope="session")
def calibration(pytestconfig: pytest.Config, profile: UnitProfile) -> CalibrationRun:
    """The calibration run collecting recordings and judged measurements for the certificate."""
    if RUN_KEY not in pytestconfig.stash:
        station_id, operator, reference = _run_context(pytestconfig)
        kind = drive_kind(pytestconfig)
        serial = pytestconfig.getoption("--unit-serial")
        if serial is None:  # a simulated unit (pytest_configure refused a real one)
            serial = "SIM-0001"
        pytestconfig.stash[RUN_KEY] = CalibrationRun(
            profile=profile,
            unit_serial=serial,
            out_dir=Path(pytestconfig.getoption("--out")),
            drive_kind=kind,
            method_bias=_method_bias(pytestconfig.getoption("--method-bias"), profile),
            station_id=station_id,
            operator=operator,
            reference=reference,
            identity=pytestconfig.stash[STATION_KEY],
            stop=pytestconfig.stash[STOP_KEY],
        )
        pytestconfig.stash[RUN_KEY].expected = {name: PROTOCOL_OF[name]
                                                 for name in profile.measurements}
    return pytestconfig.stash[RUN_KEY]


def _run_context(config: pytest.Config) -> tuple[str, str, bool]:
    """Station id, operator and reference flag for the certificate's ``run`` block."""
    station = config.stash[STATION_KEY]
    operator = (config.getoption("--operator") or os.environ.get("GIMBAL_HIL_OPERATOR")
                or _login_name())
    reference = bool(config.getoption("--reference")) or station.reference
    return station.station_id or socket.gethostname(), str(operator), reference


def _login_name() -> str:
    try:
        return getpass.getuser()
    except (KeyError, OSError):  # no passwd entry (some containers)
        return "unknown"


def _method_bias(option: str | None, profile: UnitProfile) -> MethodBiasMap | None:
    """The map ``--method-bias`` names: ``None`` for the shipped one, empty for ``off``."""
    if option is None:
        return None
    if option == "off":
        return MethodBiasMap(source="off", sha256="", entries={})
    return load_method_bias(Path(option), axis=profile.axis)


@pytest.fixture(scope="session")
def drive_connection(
    request: pytest.FixtureRequest, pytestconfig: pytest.Config, profile: UnitProfile,
    calibration: CalibrationRun
) -> Iterator[Drive]:
    """The open drive for the whole session; closed (and disabled) at the end."""
    link = pytestconfig.getoption("--gimbal-link")
    with open_drive(
        drive_kind(pytestconfig),
        profile=profile,
        unit_serial=calibration.unit_serial,
        station=pytestconfig.getoption("--station"),
        seed=pytestconfig.getoption("--seed"),
        gimbal_axes=pytestconfig.stash.get(GIMBAL_AXES_KEY, {}),
        sim_pace=pytestconfig.getoption("--sim-pace"),
        gimbal_link=link,
        protocols=() if link is None else _planned(request.session.items, profile),
    ) as drive:
        calibration.drive_info = drive.info
        yield drive


@pytest.fixture(scope="module")
def drive(request: pytest.FixtureRequest, drive_connection: Drive) -> Iterator[Drive]:
    """The drive, enabled for one protocol module; afterwards quick-stopped if anything in
    the module failed or the run was interrupted (SIGINT, SIGTERM, SIGHUP), always disabled."""
    failures_before = request.session.testsfailed
    marker = request.node.get_closest_marker(PROTOCOL_MARK)
    if marker is not None:
        drive_connection.begin_protocol(str(marker.args[0]))
    drive_connection.enable()
    try:
        yield drive_connection
    finally:
        try:
            interrupted = request.session.exitstatus == pytest.ExitCode.INTERRUPTED
            if request.session.testsfailed != failures_before or interrupted:
                drive_connection.quick_stop()
        finally:
            drive_connection.disable()
            if marker is not None:
                drive_connection.end_protocol()


@pytest.fixture(scope="module")
def drive_info(request: pytest.FixtureRequest, drive: Drive, profile: UnitProfile,
               calibration: CalibrationRun) -> DriveInfo:
    """The drive as this module's protocol sees it: streamed at the link's rate when one of
    its runs would not fit the drive's recorder (the certificate says so)."""
    from hil.suite.plan import acquisition_info

    marker = request.node.get_closest_marker("protocol")
    if marker is None:
        return drive.info
    name = str(marker.args[0])
    info, why = acquisition_info(name, profile, drive.info)
    if why is not None:
        calibration.protocol(name).messages.append(why)
    return info


@pytest.fixture(autouse=True)
def _allure_measurements(request: pytest.FixtureRequest) -> Iterator[None]:
    """With allure-pytest active, attach each protocol test's judged measurements."""
    run = request.config.stash.get(RUN_KEY, None)
    before = len(run.measurements) if run else 0
    yield
    run = request.config.stash.get(RUN_KEY, None)
    # allure-pytest registers its listener only when --alluredir asks for a report
    if run is None or not request.config.pluginmanager.hasplugin("allure_listener"):
        return
    import allure

    for measurement in run.measurements[before:]:
        allure.attach(
            json.dumps(result_record(measurement).to_json(), indent=2),
            name=measurement.spec.name,
            attachment_type=allure.attachment_type.JSON,
        )
    name = _protocol_name(request.node)
    if name is not None and _last_of_protocol(request.node, name):
        from hil.report.attachments import attach_protocol

        attach_protocol(run, name)


def _last_of_protocol(item: pytest.Item, name: str) -> bool:
    """No later test of the session belongs to protocol ``name``."""
    items = item.session.items
    later = items[items.index(item) + 1:] if item in items else []
    return all(_protocol_name(other) != name for other in later)


def _planned(items: list[pytest.Item], profile: UnitProfile) -> tuple[Planned, ...]:
    """The protocols this session will run, in order, with their planned motion and how
    each shares a gimbal with the other axis (a shared gimbal plans from them)."""
    names = list(dict.fromkeys(n for n in map(_protocol_name, items)
                               if n is not None and n in profile.protocols))
    motion = planned_motion_s(profile, _planning_info(profile))
    return tuple(Planned(name=name, motion_s=motion.get(name, 0.0),
                         beside=CATALOGUE[name].beside if name in CATALOGUE else ALONE)
                 for name in names)


def _protocol_name(item: pytest.Item) -> str | None:
    mark = item.get_closest_marker(PROTOCOL_MARK)
    if mark is None:
        return None
    return str(mark.args[0]) if mark.args else item.name


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Run protocols in the order of the profile's ``[protocols.*]`` tables (later protocols
    may use earlier results, e.g. J for an acceleration correction); others keep their place."""
    order = list(config.stash[PROFILE_KEY].protocols)
    slots = [i for i, item in enumerate(items) if _protocol_name(item) is not None]

    def rank(item: pytest.Item) -> int:
        name = _protocol_name(item)
        return order.index(name) if name in order else len(order)

    ordered = sorted((items[i] for i in slots), key=rank)
    for slot, item in zip(slots, ordered, strict=True):
        items[slot] = item


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> None:
    """Tell the operator when a protocol starts: n of N, its motion, the time left."""
    name = _protocol_name(item)
    config = item.config
    console = config.stash.get(CONSOLE_KEY, None)
    profile = config.stash[PROFILE_KEY]
    if console is None or name is None or name == console.current or name not in profile.protocols:
        return
    console.current = name
    now = time.perf_counter()
    if console.started_s is None:
        console.started_s = now
    run = config.stash.get(RUN_KEY, None)
    info = run.drive_info if run is not None and run.drive_info else _planning_info(profile)
    done = [r for r in run.protocols.values() if r.name != name] if run is not None else []
    collected = {_protocol_name(other) for other in item.session.items}
    plan = {k: v for k, v in planned_motion_s(profile, info).items() if k in collected}
    line = protocol_start(name, plan,
                          done_motion_s=sum(r.motion_time_s for r in done),
                          done_wall_s=now - console.started_s)
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None and config.get_verbosity() >= -1:
        writer = getattr(reporter, "_tw", None)  # -q: dots run on without a module's line
        if writer is not None and writer.width_of_current_line:
            reporter.write("\n")
        reporter.write_line(line, bold=True)


def _planning_info(profile: UnitProfile) -> DriveInfo:
    """The drive as the profile describes it, for the motion plan before the drive is open."""
    return DriveInfo(vendor="", model="", firmware_version="", serial="",
                     rated_torque_nm=profile.limits.torque_nm, limits=profile.limits,
                     modes=tuple(Mode), max_sample_rate_hz=profile.sample_rate_hz,
                     capabilities=frozenset(Capability), transport="planned")


def pytest_runtest_setup(item: pytest.Item) -> None:
    """No protocol starts after a stop signal. A protocol the unit's profile does not
    configure, or a result it does not declare (``gravity_phase_rad`` on an axis without
    gravity), is skipped, with the reason."""
    name = _protocol_name(item)
    if name is None:
        return
    item.config.stash[STOP_KEY].honour(f"protocol {name}")
    profile = item.config.stash[PROFILE_KEY]
    if name not in profile.protocols:
        pytest.skip(f"the unit profile has no [protocols.{name}] table: not calibrated here")
    callspec = getattr(item, "callspec", None)
    parameter = callspec.params.get("parameter") if callspec is not None else None
    if isinstance(parameter, str) and parameter not in profile.measurements:
        pytest.skip(f"the unit profile declares no [measurements.{parameter}]: not measured "
                    "on this unit")


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(
    item: pytest.Item, call: pytest.CallInfo[None]
) -> Generator[None, pytest.TestReport, pytest.TestReport]:
    report: pytest.TestReport = yield
    name = _protocol_name(item)
    run = item.config.stash.get(RUN_KEY, None)
    if name is None or run is None:
        return report
    if report.failed and call.excinfo is not None and isinstance(call.excinfo.value, HilError):
        if isinstance(call.excinfo.value, StorageError):  # a full disk: no further motion
            item.session.shouldstop = str(call.excinfo.value)
        return _refused(item, name, call.excinfo.value, report, run)
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


def _refused(item: pytest.Item, name: str, error: HilError, report: pytest.TestReport,
             run: CalibrationRun) -> pytest.TestReport:
    """A protocol the drive, the link or the analysis refused (a :class:`HilError`) says
    so once, in one line: the first of its tests errors with the message (no traceback, it
    is no bug) and the certificate records it; the protocol's other results, stopped by the
    same error, are reported as not measured instead of repeating it."""
    refusals = item.config.stash.setdefault(REFUSALS_KEY, [])
    if any(error is seen for seen in refusals):
        report.outcome = "skipped"
        report.longrepr = (str(item.path), (item.location[1] or 0) + 1,
                           f"not measured: protocol {name} stopped (its error is above)")
        return report
    refusals.append(error)
    report.longrepr = f"{name}: {error}"
    run.report_protocol(name, Outcome.ERROR, str(error))
    return report


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Generator[None, None, None]:
    """Each measurement a protocol's test judged, as properties of its JUnit test case."""
    run = item.config.stash.get(RUN_KEY, None)
    before = len(run.measurements) if run is not None else 0
    try:
        return (yield)
    finally:
        run = item.config.stash.get(RUN_KEY, None)
        for measurement in run.measurements[before:] if run is not None else []:
            item.user_properties.extend(measurement_properties(result_record(measurement)))


@pytest.hookimpl(tryfirst=True)  # before junitxml's own sessionfinish writes its file
def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    run = session.config.stash.get(RUN_KEY, None)
    if run is None or not run.active:
        return
    aborted = (exitstatus == pytest.ExitCode.INTERRUPTED or session.shouldstop is not False
               or session.config.stash[STOP_KEY].asked)
    try:
        path = write_certificate(run, aborted=bool(aborted))
    except OSError as exc:  # nothing half-written (atomic writes); no certificate to store
        failure = storage_error(exc, exc.filename or run.unit_dir / "certificate.json")
        session.config.stash[STORAGE_FAILURE_KEY] = str(failure)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
        return
    session.config.stash[CERTIFICATE_KEY] = path
    if run.overall_outcome(aborted=bool(aborted)) == Outcome.INCOMPLETE and exitstatus == 0:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED  # every test passed, not every result
    _junit_suite(session.config, path)
    # the store (or outbox) before the documents: a stop while they render loses no run
    option = session.config.getoption("--store")
    if option != "off":  # the certificate is written: a failing store only queues the run
        out_dir = Path(session.config.getoption("--out"))
        url = resolve_store_url(
            option, out_dir=out_dir, station_store=session.config.stash[STATION_KEY].store
        )
        message = record_run(path, out_dir=out_dir, url=url)
        log.info("%s", message)
        session.config.stash[STORE_MESSAGE_KEY] = message
    if not session.config.getoption("--no-documents"):
        from hil.report.documents import write_documents  # matplotlib: only if drawn

        session.config.stash[DOCUMENTS_KEY] = write_documents(path)


def _junit_suite(config: pytest.Config, certificate: Path) -> None:
    """With ``--junitxml``: the suite named after the unit (unless ``junit_suite_name`` was
    set) and the certificate's identity as its properties."""
    from _pytest.junitxml import xml_key  # the key record_testsuite_property uses

    xml = config.stash.get(xml_key, None)
    if xml is None:
        return
    cert = read_certificate(certificate)
    if config.getini("junit_suite_name") == PYTEST_DEFAULT_SUITE_NAME:
        xml.suite_name = suite_name(cert.unit.serial)
    for name, value in junit_suite_properties(cert):
        xml.add_global_property(name, value)


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    config = terminalreporter.config
    path = config.stash.get(CERTIFICATE_KEY, None)
    run = config.stash.get(RUN_KEY, None)
    if STORAGE_FAILURE_KEY in config.stash:
        terminalreporter.write_line(f"gimbal-hil: error: {config.stash[STORAGE_FAILURE_KEY]}",
                                    red=True, bold=True)
    if path is None or run is None:
        return
    terminalreporter.section("gimbal-hil calibration")
    for m in run.measurements:
        value, expanded = rounded_pair(m.estimate.value, m.estimate.expanded_uncertainty)
        terminalreporter.write_line(
            f"{m.spec.name:<32}{value:>12} ± {expanded:<9}{m.spec.unit:<11}{m.outcome.value}"
        )
    cert = read_certificate(path)
    outcome = cert.outcome
    problems = config.stash.get(DOCUMENTS_KEY, [])
    documents = () if config.getoption("--no-documents") else (
        "certificate.html", "certificate.pdf")
    beside = ["certificate.txt"] + [name for name in documents
                                    if not any(p.startswith(name) for p in problems)]
    terminalreporter.write_line(f"certificate: {path} (and {', '.join(beside)} beside it)")
    for problem in problems:
        terminalreporter.write_line(f"not rendered: {problem}", yellow=True)
    colour = {"PASS": "green", "MARGINAL": "yellow"}.get(outcome, "red")
    for line in outcome_banner(outcome, aborted=cert.aborted):
        terminalreporter.write_line(line, **{colour: True, "bold": True})
    if STORE_MESSAGE_KEY in config.stash:
        terminalreporter.write_line(config.stash[STORE_MESSAGE_KEY])
    terminalreporter.write_line(f"unit {run.unit_serial}: {outcome}")
