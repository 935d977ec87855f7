"""What pytest's JUnit XML (``--junitxml``) says about a calibration, so that CI dashboards
and line MES tools reading JUnit can tell units apart and read the results: the test suite
named after the unit, the certificate's identity as suite properties, and each judged
measurement as properties of the protocol test case that judged it.

Pure functions over the certificate's entries; :mod:`hil.calibration_session` (the pytest
layer) hands them to pytest's ``LogXML`` and each item's ``user_properties``.
"""

from __future__ import annotations

from pathlib import PurePath

from hil.certificate.model import Certificate, Result

#: pytest's ``junit_suite_name`` when nobody set one: the calibration then names the unit.
PYTEST_DEFAULT_SUITE_NAME = "pytest"


def suite_name(unit_serial: str) -> str:
    """The test suite's name for a unit: ``gimbal-hil <serial>``."""
    return f"gimbal-hil {unit_serial}"


def suite_properties(cert: Certificate) -> list[tuple[str, str]]:
    """The certificate's identity as ``(name, value)`` suite properties.

    Parameters
    ----------
    cert : Certificate
        ``certificate.json`` as read (:func:`hil.certificate.model.read_certificate`).

    Returns
    -------
    list of (str, str)
        Serial, unit type, profile name (not its path: the SHA-256 is the record) and
        SHA-256, certificate id, overall outcome, drive kind, station and run id; a field
        the certificate lacks is left out.
    """
    run = cert.run
    found: tuple[tuple[str, str | None], ...] = (
        ("unit_serial", cert.unit.serial), ("unit_type", cert.unit.unit_type),
        ("profile", PurePath(cert.method.profile).stem),  # a built-in's name, a file's stem
        ("profile_sha256", cert.method.profile_sha256),
        ("certificate_id", cert.certificate_id), ("outcome", cert.outcome),
        ("drive", cert.drive.kind), ("station", run.station if run else None),
        ("run_id", run.id if run else None))
    return [(name, value) for name, value in found if value is not None]


def measurement_properties(result: Result) -> list[tuple[str, str]]:
    """One judged measurement as ``<parameter>.<field>`` properties: value, U (expanded),
    k, unit, limits and outcome, numbers at full precision (as ``certificate.json``).

    Parameters
    ----------
    result : Result
        The measurement as the certificate states it
        (:func:`hil.certificate.build.result_record`).

    Returns
    -------
    list of (str, str)
    """
    fields = (("value", result.value), ("U", result.expanded_uncertainty),
              ("k", result.coverage_factor), ("unit", result.unit),
              ("lower_limit", result.lower_limit), ("upper_limit", result.upper_limit),
              ("outcome", result.outcome))
    return [(f"{result.parameter}.{field}", _text(value)) for field, value in fields]


def _text(value: object) -> str:
    """A number as Python's shortest round-trip form (``inf`` for an open limit), else as is."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return str(value)
    return repr(float(value))
