"""The typed certificate (hil/certificate/model.py): one writer, one reader, the same bytes.

Every certificate ``write_certificate`` writes is read back by the reader before it is
written (so every test that calibrates reads one); here the round trip, the refusals and
the readers that read the model are held to it."""

from __future__ import annotations

import copy
import dataclasses
import json
from pathlib import Path
from typing import Any

import pytest

from hil.certificate import build
from hil.certificate.model import (
    SCHEMA,
    Certificate,
    CertificateError,
    Result,
    read_certificate,
)
from hil.certificate.render import render_text
from hil.report.view import certificate_view
from tests.report.runs import Run


def _document(run: Run) -> dict[str, Any]:
    document: dict[str, Any] = json.loads((run.unit_dir / "certificate.json").read_bytes())
    return document


@pytest.mark.parametrize("which", ["elevation_run", "failed_run"])
def test_a_written_certificate_reads_and_writes_back_byte_for_byte(
    which: str, request: pytest.FixtureRequest
) -> None:
    run: Run = request.getfixturevalue(which)
    path = run.unit_dir / "certificate.json"
    cert = read_certificate(path)
    assert read_certificate(run.unit_dir) == cert  # the unit's directory names it too
    written = (json.dumps(cert.to_json(), indent=2) + "\n").encode("utf-8")
    assert written == path.read_bytes()
    assert Certificate.from_json(json.loads(written)) == cert
    assert cert.schema == SCHEMA == build.SCHEMA
    assert cert.integrity is not None
    assert all(isinstance(r, Result) for r in cert.results)


def test_the_text_certificate_is_rendered_from_the_model(elevation_run: Run) -> None:
    cert = read_certificate(elevation_run.unit_dir)
    text = (elevation_run.unit_dir / "certificate.txt").read_text(encoding="utf-8")
    assert render_text(cert) == text
    assert render_text(_document(elevation_run)) == text  # a parsed document is read first
    assert certificate_view(cert) == certificate_view(_document(elevation_run))


def test_a_renamed_field_is_written_under_its_own_key(elevation_run: Run) -> None:
    cert = read_certificate(elevation_run.unit_dir)
    document = cert.to_json()
    assert document["unit"]["type"] == cert.unit.unit_type
    assert document["results"][0]["budget"][0]["type"] == cert.results[0].budget[0].kind
    assert document["drive"]["kind"] == cert.drive.kind
    assert document["drive"]["transport"] == cert.drive.transport
    unheld = next(f for f in document["raw_data"])
    assert "held_axes" not in unheld  # written only when a gimbal's axes were held


def _refused(document: object, tmp_path: Path) -> str:
    path = tmp_path / "certificate.json"
    path.write_text(json.dumps(document), encoding="utf-8")
    with pytest.raises(CertificateError) as caught:
        read_certificate(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: "), message
    assert "\n" not in message
    return message


def test_another_schema_is_refused(elevation_run: Run, tmp_path: Path) -> None:
    document = _document(elevation_run)
    document["schema"] = "gimbal-hil/certificate/v2"
    assert "schema 'gimbal-hil/certificate/v2' is not 'gimbal-hil/certificate/v1'" in (
        _refused(document, tmp_path))
    document["schema"] = "something/else"
    assert "not a gimbal-hil certificate (schema 'something/else')" in _refused(document,
                                                                              tmp_path)
    assert "not a gimbal-hil certificate (schema None)" in _refused({"results": []}, tmp_path)
    assert "not a JSON object" in _refused([1, 2], tmp_path)


def test_a_missing_key_is_refused_naming_it(elevation_run: Run, tmp_path: Path) -> None:
    document = _document(elevation_run)
    del document["results"][2]["value"]
    assert _refused(document, tmp_path).endswith(": results[2].value is missing")
    document = _document(elevation_run)
    del document["unit"]["serial"]
    assert _refused(document, tmp_path).endswith(": unit.serial is missing")
    document = _document(elevation_run)
    del document["outcome"]
    assert _refused(document, tmp_path).endswith(": outcome is missing")


def test_a_mistyped_key_is_refused_naming_it(elevation_run: Run, tmp_path: Path) -> None:
    document = _document(elevation_run)
    document["results"][1]["expanded_uncertainty"] = "0.01"
    assert _refused(document, tmp_path).endswith(
        ": results[1].expanded_uncertainty must be a number, not a string")
    document = _document(elevation_run)
    document["results"][0]["budget"][0]["type"] = 1
    assert _refused(document, tmp_path).endswith(
        ": results[0].budget[0].type must be a string, not a number")
    document = _document(elevation_run)
    document["aborted"] = "no"
    assert _refused(document, tmp_path).endswith(": aborted must be a boolean, not a string")
    document = _document(elevation_run)
    document["raw_data"][0]["samples"] = 1.5
    assert _refused(document, tmp_path).endswith(
        ": raw_data[0].samples must be an integer, not a number")
    document = _document(elevation_run)
    document["method"]["protocols"] = []
    assert _refused(document, tmp_path).endswith(
        ": method.protocols must be an object, not a list")
    document = _document(elevation_run)
    document["outcome"] = "GOOD"
    assert "outcome is 'GOOD'" in _refused(document, tmp_path)


def test_an_unknown_key_is_refused_naming_it(elevation_run: Run, tmp_path: Path) -> None:
    document = _document(elevation_run)
    document["results"][0]["valeu"] = 1.0
    assert _refused(document, tmp_path).endswith(
        f": results[0].valeu is not a key of a certificate of {SCHEMA}")


def test_a_certificate_written_before_later_fields_still_reads(elevation_run: Run) -> None:
    old = copy.deepcopy(_document(elevation_run))
    for r in old["results"]:
        for key in ("title", "description", "non_negative", "direction", "validation"):
            r.pop(key)
    for key in ("laboratory", "customer", "authorised_by", "environment", "run",
                "not_measured", "artifacts", "integrity", "conditions"):
        old.pop(key)
    for key in ("profile_sha256_without_firmware", "method_bias", "details"):
        old["method"].pop(key)
    cert = read_certificate(old)
    assert cert.results[0].shown_title == cert.results[0].parameter
    assert cert.integrity is None
    assert cert.method.method_bias is None
    assert "not authorised" in render_text(cert)


def test_the_builder_gives_what_the_file_holds(elevation_run: Run) -> None:
    cert = read_certificate(elevation_run.unit_dir)
    assert dataclasses.replace(cert, integrity=None).to_json() == {
        k: v for k, v in _document(elevation_run).items() if k != "integrity"}
