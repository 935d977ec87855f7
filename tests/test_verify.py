"""Integrity (issue 26): the certificate's digest, its recordings' SHA-256 and its outcomes
are checked by ``gimbal-hil verify``, and ``compare``, ``results ingest`` and ``render``
refuse a tampered certificate in one line (ingest skips it and stores the good ones)."""

from __future__ import annotations

import json
import logging
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from hil.characterise.processes import run_command
from hil.cli import main

SERIAL = "VERIFY-1"


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real simulated calibration (one protocol, no store, no documents): its unit folder."""
    out = tmp_path_factory.mktemp("verify")
    done = run_command(
        ["calibrate", "--drive", "sim", "--unit-serial",
         SERIAL, "--out", str(out), "--", "--store", "off", "--no-documents",
         "-k", "inertia_friction"],
        timeout_s=600)
    unit = out / SERIAL
    assert (unit / "certificate.json").is_file(), done.stdout[-3000:] + done.stderr[-3000:]
    return unit


def copy(unit: Path, where: Path) -> Path:
    """The unit folder copied to ``where/SERIAL`` (a side of its own)."""
    target = where / SERIAL
    shutil.copytree(unit, target)
    return target


def load(unit: Path) -> dict[str, Any]:
    document: dict[str, Any] = json.loads((unit / "certificate.json").read_text("utf-8"))
    return document


def save(unit: Path, document: dict[str, Any]) -> None:
    (unit / "certificate.json").write_text(json.dumps(document, indent=2), encoding="utf-8")


def edit_value(unit: Path) -> str:
    document = load(unit)
    document["results"][0]["value"] *= 1.001
    save(unit, document)
    return "content changed after it was written"


def edit_outcome(unit: Path) -> str:
    document = load(unit)
    document["outcome"] = "FAIL" if document["outcome"] != "FAIL" else "PASS"
    save(unit, document)
    return "content changed after it was written"


def edit_recording(unit: Path) -> str:
    name = load(unit)["raw_data"][0]["file"]
    data = bytearray((unit / name).read_bytes())
    data[len(data) // 2] ^= 0xFF
    (unit / name).write_bytes(bytes(data))
    return f"recording {name} changed"


def delete_recording(unit: Path) -> str:
    name = load(unit)["raw_data"][-1]["file"]
    (unit / name).unlink()
    return f"recording {name} is missing"


def forge_outcome(unit: Path) -> str:
    """A value moved outside its limits and the digest recomputed (a careful forger): the
    outcomes no longer follow from the results."""
    from hil.certificate.integrity import seal

    document = load(unit)
    result = document["results"][0]
    result["value"] = result["upper_limit"] + abs(result["upper_limit"]) + 1.0
    save(unit, seal(document))
    return f"result {result['parameter']}: outcome {result['outcome']} contradicts"


TAMPERS: dict[str, Callable[[Path], str]] = {
    "value": edit_value, "outcome": edit_outcome, "recording": edit_recording,
    "deleted": delete_recording, "forged": forge_outcome,
}


@pytest.fixture(params=list(TAMPERS))
def tampered(request: pytest.FixtureRequest, calibrated: Path,
             tmp_path: Path) -> tuple[Path, str]:
    """A tampered copy of the calibrated unit and what verify must say about it."""
    unit = copy(calibrated, tmp_path / "tampered")
    return unit, TAMPERS[request.param](unit)


def test_an_untampered_certificate_is_verified(calibrated: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["verify", str(calibrated)]) == 0
    assert capsys.readouterr().out == f"{calibrated / 'certificate.json'}: VERIFIED\n"
    document = load(calibrated)
    assert len(document["integrity"]["content_sha256"]) == 64


def test_verify_names_what_was_tampered(tampered: tuple[Path, str],
                                        capsys: pytest.CaptureFixture[str]) -> None:
    unit, expected = tampered
    assert main(["verify", str(unit / "certificate.json")]) == 1
    lines = capsys.readouterr().out.splitlines()
    assert lines[-1] == f"{unit / 'certificate.json'}: NOT VERIFIED"
    assert any(expected in line for line in lines[:-1]), lines


def test_compare_refuses_a_tampered_certificate_in_one_line(
        calibrated: Path, tampered: tuple[Path, str],
        capsys: pytest.CaptureFixture[str]) -> None:
    unit, expected = tampered
    assert main(["compare", str(calibrated), str(unit)]) == 2
    captured = capsys.readouterr()
    (line,) = captured.err.splitlines()
    assert line.startswith(f"gimbal-hil: error: {unit / 'certificate.json'}: not verified: ")
    assert expected in line
    assert captured.out == ""


def test_render_refuses_a_tampered_certificate_in_one_line(
        calibrated: Path, tampered: tuple[Path, str], capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    import hil.report.documents

    drawn: list[Path] = []
    monkeypatch.setattr(hil.report.documents, "write_documents",
                        lambda path: drawn.append(path) or [])
    assert main(["render", str(calibrated)]) == 0  # the untampered one is drawn
    assert drawn == [calibrated / "certificate.json"]
    capsys.readouterr()
    unit, expected = tampered
    assert main(["render", str(unit)]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"gimbal-hil: error: {unit / 'certificate.json'}: not verified: ")
    assert expected in line
    assert drawn == [calibrated / "certificate.json"]  # nothing drawn from altered data


def _stored(store: Path) -> list[str]:
    from hil.store import open_store
    from hil.store.query import history

    opened = open_store(f"sqlite:///{store}")
    try:
        return [run.certificate_id for run in history(opened, SERIAL)] + \
            [run.certificate_id for run in history(opened, "GOOD-1")]
    finally:
        opened.close()


def _good_beside(calibrated: Path, folder: Path) -> str:
    """An untampered certificate of another serial in ``folder`` (its id)."""
    good = folder / "GOOD-1"
    shutil.copytree(calibrated, good)
    return str(load(good)["certificate_id"])


def test_ingest_skips_a_tampered_certificate_and_stores_the_good_one_beside_it(
        calibrated: Path, tampered: tuple[Path, str], tmp_path: Path,
        caplog: pytest.LogCaptureFixture) -> None:
    unit, expected = tampered
    good_id = _good_beside(calibrated, unit.parent)
    store = tmp_path / "store.sqlite"
    with caplog.at_level(logging.WARNING):
        assert main(["results", "ingest", str(unit.parent), "--store", f"sqlite:///{store}"]) == 0
    assert _stored(store) == [good_id]
    (warning,) = [r.getMessage() for r in caplog.records if "not stored" in r.getMessage()]
    assert str(unit / "certificate.json") in warning
    assert expected in warning


def test_ingest_of_one_tampered_file_is_refused_in_one_line(
        tampered: tuple[Path, str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    unit, expected = tampered
    store = tmp_path / "store.sqlite"
    code = main(["results", "ingest", str(unit / "certificate.json"),
                 "--store", f"sqlite:///{store}"])
    assert code == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert str(unit / "certificate.json") in line
    assert expected in line


def test_an_empty_certificate_does_not_stop_ingest_of_the_good_ones(
        calibrated: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    folder = tmp_path / "units"
    good_id = _good_beside(calibrated, folder)
    (folder / "EMPTY-1").mkdir()
    (folder / "EMPTY-1" / "certificate.json").write_bytes(b"")
    store = tmp_path / "store.sqlite"
    with caplog.at_level(logging.WARNING):
        assert main(["results", "ingest", str(folder), "--store", f"sqlite:///{store}"]) == 0
    assert _stored(store) == [good_id]
    assert any("EMPTY-1" in r.getMessage() and "not stored" in r.getMessage()
               for r in caplog.records)


def test_an_empty_certificate_is_unreadable_for_verify(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    empty = tmp_path / "certificate.json"
    empty.write_bytes(b"")
    assert main(["verify", str(empty)]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"gimbal-hil: error: {empty}: empty file")


def _old(calibrated: Path, where: Path) -> Path:
    """The certificate as written before digests (none in it)."""
    unit = copy(calibrated, where)
    document = load(unit)
    del document["integrity"]
    save(unit, document)
    return unit


def test_a_certificate_without_digest_is_not_verified_but_said_why(
        calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    unit = _old(calibrated, tmp_path)
    assert main(["verify", str(unit)]) == 1
    lines = capsys.readouterr().out.splitlines()
    assert lines == [f"{unit / 'certificate.json'}: no digest (written before gimbal-hil "
                     "certificates carried one, issue 26): its content cannot be verified",
                     f"{unit / 'certificate.json'}: NOT VERIFIED"]


def test_a_certificate_without_digest_is_still_read_with_a_warning(
        calibrated: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture,
        monkeypatch: pytest.MonkeyPatch) -> None:
    import hil.report.documents

    unit = _old(calibrated, tmp_path / "old")
    monkeypatch.setattr(hil.report.documents, "write_documents", lambda path: [])
    store = tmp_path / "store.sqlite"
    with caplog.at_level(logging.WARNING):
        assert main(["compare", str(calibrated), str(unit)]) == 0
        assert main(["render", str(unit)]) == 0
        assert main(["results", "ingest", str(unit.parent),
                     "--store", f"sqlite:///{store}"]) == 0
    assert _stored(store) == [load(unit)["certificate_id"]]
    warned = [r.getMessage() for r in caplog.records if "no digest" in r.getMessage()]
    assert len(warned) == 3  # compare, render, ingest
    # a recording of an old certificate is still held to its listed SHA-256
    delete_recording(unit)
    assert main(["compare", str(calibrated), str(unit)]) == 2


def test_comparing_a_certificate_with_itself_warns_in_one_line(
        calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    again = copy(calibrated, tmp_path)
    assert main(["compare", str(calibrated), str(again)]) == 0
    err = capsys.readouterr().err.splitlines()
    same = [line for line in err if "same certificate" in line]
    assert same == [f"gimbal-hil compare: warning: {calibrated / 'certificate.json'} and "
                    f"{again / 'certificate.json'} are the same certificate "
                    f"({load(calibrated)['certificate_id']}): the run is compared with itself"]


def test_the_digest_covers_everything_but_itself() -> None:
    from hil.certificate.integrity import content_digest, seal

    document = seal({"b": [1, 2.5, None], "a": {"y": "é", "x": (1, 2)}})
    assert set(document) == {"a", "b", "integrity"}
    stated = document["integrity"]["content_sha256"]
    assert content_digest(document) == stated
    assert content_digest({**document, "integrity": {"content_sha256": "0"}}) == stated
    assert content_digest({**document, "b": [1, 2.5, 0]}) != stated


def test_parsing_verify_loads_no_subcommand_dependency() -> None:
    script = (
        "import argparse, sys\n"
        "original = argparse.ArgumentParser.parse_args\n"
        "def parse_only(self, args=None, namespace=None):\n"
        "    original(self, args, namespace)\n"
        "    print('PARSED')\n"
        "    raise SystemExit(0)\n"
        "argparse.ArgumentParser.parse_args = parse_only\n"
        "from hil.cli import main\n"
        "try:\n"
        "    main(['verify', 'x'])\n"
        "except SystemExit:\n"
        "    pass\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'numpy', 'scipy', "
        "'sqlalchemy', 'matplotlib', 'numba', 'pytest'}))\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == ["PARSED", "[]"], done.stdout + done.stderr


@pytest.mark.parametrize(("rule_knows_bounds", "outcome"), [(True, "PASS"), (False, "MARGINAL")])
def test_a_certificate_is_judged_by_its_own_decision_rule(
    calibrated: Path, tmp_path: Path, rule_knows_bounds: bool, outcome: str
) -> None:
    """A spread of 0.5 ± 1 % against [-0.001, 5]: PASS by today's rule (a quantity that
    cannot be negative crosses no lower limit at or below zero), MARGINAL by the rule a
    certificate issued before it states; each verifies under its own rule and not the
    other's outcome."""
    from hil.certificate.integrity import seal, verify_document

    document = load(calibrated)
    spread = next(r for r in document["results"]
                  if r["parameter"] == "inertia_amplitude_spread_pct")
    assert spread["non_negative"] is True
    spread.update(value=0.5, expanded_uncertainty=1.0, lower_limit=-0.001, upper_limit=5.0)
    if not rule_knows_bounds:
        document["decision_rule"] = document["decision_rule"].split(" A quantity")[0]
    for stated, holds in ((outcome, True), ({"PASS": "MARGINAL"}.get(outcome, "PASS"), False)):
        spread["outcome"] = stated
        verification = verify_document(seal(document), path=tmp_path / "c.json", unit_dir=None)
        problems = [p for p in verification.outcomes if "inertia_amplitude_spread" in p]
        assert (problems == []) is holds, (stated, problems)
