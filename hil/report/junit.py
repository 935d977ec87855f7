"""What pytest's JUnit XML (``--junitxml``) says about a calibration, so that CI dashboards
and line MES tools reading JUnit can tell units apart and read the results: the test suite
named after the unit, the certificate's identity as suite properties, and each judged
measurement as properties of the protocol test case that judged it.

Pure functions over the certificate's entries; :mod:`hil.calibration_session` (the pytest
layer) hands them to pytest's ``LogXML`` and each item's ``user_properties``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import PurePath
from typing import Any

#: pytest's ``junit_suite_name`` when nobody set one: the calibration then names the unit.
PYTEST_DEFAULT_SUITE_NAME = "pytest"
#: The suite's properties and where the certificate keeps each.
SUITE_FIELDS = (("unit_serial", ("unit", "serial")), ("unit_type", ("unit", "type")),
                ("profile", ("method", "profile")),
                ("profile_sha256", ("method", "profile_sha256")),
                ("certificate_id", ("certificate_id",)), ("outcome", ("outcome",)),
                ("drive", ("drive", "kind")), ("station", ("run", "station")),
                ("run_id", ("run", "id")))
#: A measurement's properties, ``<parameter>.<field>``, and the certificate key of each.
MEASUREMENT_FIELDS = (("value", "value"), ("U", "expanded_uncertainty"),
                      ("k", "coverage_factor"), ("unit", "unit"),
                      ("lower_limit", "lower_limit"), ("upper_limit", "upper_limit"),
                      ("outcome", "outcome"))


def suite_name(unit_serial: str) -> str:
    """The test suite's name for a unit: ``gimbal-hil <serial>``."""
    return f"gimbal-hil {unit_serial}"


def suite_properties(cert: Mapping[str, Any]) -> list[tuple[str, str]]:
    """The certificate's identity as ``(name, value)`` suite properties.

    Parameters
    ----------
    cert : mapping
        ``certificate.json`` as written.

    Returns
    -------
    list of (str, str)
        Serial, unit type, profile name (not its path: the SHA-256 is the record) and
        SHA-256, certificate id, overall outcome, drive kind, station and run id; a field
        the certificate lacks is left out.
    """
    out = []
    for name, path in SUITE_FIELDS:
        found: Any = cert
        for key in path:
            found = found.get(key) if isinstance(found, Mapping) else None
        if found is not None:
            out.append((name, _profile_name(found) if name == "profile" else str(found)))
    return out


def _profile_name(profile: object) -> str:
    """The profile's name: a built-in name as is, a file's name without its folder."""
    return PurePath(str(profile)).stem


def measurement_properties(result: Mapping[str, Any]) -> list[tuple[str, str]]:
    """One judged measurement as ``<parameter>.<field>`` properties: value, U (expanded),
    k, unit, limits and outcome, numbers at full precision (as ``certificate.json``).

    Parameters
    ----------
    result : mapping
        The measurement as the certificate's ``results`` writes it
        (:meth:`hil.measurement.Measurement.as_dict`).

    Returns
    -------
    list of (str, str)
    """
    name = result["parameter"]
    return [(f"{name}.{field}", _text(result[key])) for field, key in MEASUREMENT_FIELDS]


def _text(value: object) -> str:
    """A number as Python's shortest round-trip form (``inf`` for an open limit), else as is."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return str(value)
    return repr(float(value))
