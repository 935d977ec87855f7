"""The command line's conventions (issue 24): ``--version``; help and the default of every
option; the command list without argparse's ``{a,b,c}``; a real unit's serial; a reading
``results`` command never creates a store; ``compare`` ends with its verdict; the start-up
loads no subcommand's dependencies (checked by what is imported, not by timing)."""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from collections.abc import Iterator
from importlib.metadata import version
from pathlib import Path

import pytest

from hil.cli import main
from hil.drives.kinds import DRIVE_KINDS, SIMULATED_KINDS
from tests.compare.certificate_factory import certificate, result, write

REAL_KINDS = tuple(k for k in DRIVE_KINDS if k not in SIMULATED_KINDS)
HEAVY = ("numpy", "scipy", "sqlalchemy", "matplotlib", "numba", "pytest", "alembic")
COMMANDS = ("simulate", "calibrate", "render", "diagnose", "results", "compare", "verify",
            "characterise")
RESULTS_COMMANDS = ("ingest", "sync", "units", "history", "trend", "spc", "export", "yield",
                    "report")


def all_parsers(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
                ) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """The parser and every (sub-)subcommand's, with its command path."""
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from all_parsers(sub, (*path, name))


class _CaughtParserError(Exception):
    """Raised in place of parsing: carries the parser ``main`` built."""


def main_parser() -> argparse.ArgumentParser:
    """The parser :func:`hil.cli.main` builds (caught as it is about to parse)."""
    original = argparse.ArgumentParser.parse_args

    def catch(self: argparse.ArgumentParser, *_: object, **__: object) -> argparse.Namespace:
        raise _CaughtParserError(self)

    argparse.ArgumentParser.parse_args = catch  # type: ignore[assignment,method-assign]
    try:
        main([])
    except _CaughtParserError as parsed:
        parser: argparse.ArgumentParser = parsed.args[0]
        return parser
    finally:
        argparse.ArgumentParser.parse_args = original  # type: ignore[method-assign]
    raise AssertionError("main() parsed no arguments")


def in_required_group(parser: argparse.ArgumentParser, action: argparse.Action) -> bool:
    return any(group.required and action in group._group_actions
               for group in parser._mutually_exclusive_groups)


# -- --version and help ---------------------------------------------------------------------
def test_version_prints_the_installed_version_and_exits_0(
        capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["--version"])
    assert exited.value.code == 0
    assert capsys.readouterr().out == f"gimbal-hil {version('gimbal-hil')}\n"


def test_every_subcommand_is_in_the_parser() -> None:
    paths = {path for path, _ in all_parsers(main_parser())}
    assert {(c,) for c in COMMANDS} <= paths
    assert {("results", c) for c in RESULTS_COMMANDS} <= paths


def test_every_argument_has_help_and_every_option_shows_its_default() -> None:
    missing: list[str] = []
    for path, parser in all_parsers(main_parser()):
        formatter = parser._get_formatter()
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction | argparse._VersionAction):
                continue
            where = " ".join(("gimbal-hil", *path, *(action.option_strings or [action.dest])))
            shown = formatter._expand_help(action) if action.help else ""
            if not shown.strip() or action.help == argparse.SUPPRESS:
                missing.append(f"{where}: no help")
                continue
            if not action.option_strings or action.required or in_required_group(parser, action):
                continue
            if "default" not in shown:
                missing.append(f"{where}: no default in {shown!r}")
            elif (action.default is not None and action.default is not False
                  and str(action.default) not in shown):
                missing.append(f"{where}: default {action.default!r} not in {shown!r}")
    assert not missing, "\n".join(missing)


@pytest.mark.parametrize(("argv", "names"), [([], COMMANDS), (["results"], RESULTS_COMMANDS)])
def test_the_command_list_has_one_line_per_command_and_no_braces(
        argv: list[str], names: tuple[str, ...], capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "80")
    with pytest.raises(SystemExit):
        main([*argv, "--help"])
    out = capsys.readouterr().out
    assert "{" not in out, out
    # the list: every line is one command and its description (none wraps on 80 columns)
    listed = [line for line in out.split("\ncommands:\n", 1)[-1].splitlines()[1:] if line]
    found = [re.match(r"    (\S+) +\S", line) for line in listed]
    assert all(found), out
    assert [m.group(1) for m in found if m] == list(names), out


def test_no_help_shows_braces() -> None:
    for path, parser in all_parsers(main_parser()):
        assert "{" not in parser.format_help(), path


# -- calibrate: the unit's serial -------------------------------------------------------------
@pytest.fixture
def pytest_runs(monkeypatch: pytest.MonkeyPatch) -> list[list[str]]:
    """The argument lists ``calibrate`` handed to pytest (pytest itself is not run)."""
    calls: list[list[str]] = []

    def fake_main(args: list[str]) -> int:
        calls.append(list(args))
        return 0

    monkeypatch.setattr(pytest, "main", fake_main)
    return calls


@pytest.mark.parametrize("kind", REAL_KINDS)
def test_calibrate_refuses_a_real_unit_without_its_serial_before_pytest(
        kind: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        pytest_runs: list[list[str]]) -> None:
    assert main(["calibrate", "--drive", kind, "--out", str(tmp_path)]) == 2
    captured = capsys.readouterr()
    (line,) = captured.err.splitlines()
    assert line.startswith("gimbal-hil: error: ")
    assert "--unit-serial" in line
    assert captured.out == ""
    assert pytest_runs == []


@pytest.mark.parametrize("kind", ["sim", REAL_KINDS[0]])
@pytest.mark.parametrize("serial", ["", "  "])
def test_calibrate_refuses_a_blank_serial(
        kind: str, serial: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        pytest_runs: list[list[str]]) -> None:
    code = main(["calibrate", "--drive", kind, "--unit-serial", serial, "--out", str(tmp_path)])
    (line,) = capsys.readouterr().err.splitlines()
    assert code == 2
    assert line.startswith("gimbal-hil: error: --unit-serial")
    assert pytest_runs == []


def test_a_simulated_unit_needs_no_serial(tmp_path: Path, pytest_runs: list[list[str]]) -> None:
    assert main(["calibrate", "--drive", "sim", "--out", str(tmp_path)]) == 0
    (args,) = pytest_runs
    assert "--unit-serial" not in args


def test_the_serial_help_says_the_default_is_the_simulators() -> None:
    (calibrate,) = [p for path, p in all_parsers(main_parser()) if path == ("calibrate",)]
    (action,) = [a for a in calibrate._actions if "--unit-serial" in a.option_strings]
    shown = " ".join(calibrate._get_formatter()._expand_help(action).split())
    assert "SIM-0001" in shown
    assert "simulator" in shown
    assert "required with a real drive" in shown


# -- results: reading never creates a store ---------------------------------------------------
READING = [
    ("units",), ("history", "SN-1"), ("trend", "inertia_kg_m2"), ("spc", "inertia_kg_m2"),
    ("export", "inertia_kg_m2", "--output", "x.csv"), ("yield",), ("report", "--html", "x.html"),
]


@pytest.mark.parametrize("exists", [True, False], ids=["empty-dir", "no-dir"])
@pytest.mark.parametrize("command", READING, ids=[c[0] for c in READING])
def test_a_reading_results_command_does_not_create_a_store(
        command: tuple[str, ...], exists: bool, tmp_path: Path,
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("GIMBAL_HIL_STORE", raising=False)
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "nowhere"
    if exists:
        out.mkdir()
    code = main(["results", *command, "--out", str(out)])
    captured = capsys.readouterr()
    (line,) = captured.err.splitlines()
    assert code == 2
    assert line.startswith("gimbal-hil: error: no results store in ")
    assert captured.out == ""
    assert out.exists() == exists
    assert not (out / "results.sqlite").exists()


def test_a_reading_command_on_a_missing_store_file_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "other.sqlite"
    assert main(["results", "units", "--store", f"sqlite:///{missing}"]) == 2
    assert "no results store" in capsys.readouterr().err
    assert not missing.exists()


def test_a_writing_results_command_still_creates_the_store(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("GIMBAL_HIL_STORE", raising=False)
    out = tmp_path / "new"
    assert main(["results", "sync", "--out", str(out)]) == 0
    assert (out / "results.sqlite").is_file()
    assert main(["results", "units", "--out", str(out)]) == 0
    assert "no runs stored" in capsys.readouterr().out


# -- compare: the verdict last ----------------------------------------------------------------
@pytest.mark.parametrize(("candidate_value", "verdict", "code"),
                         [(1.0, "SAME", 0), (0.9, "WORSE", 1), (1.1, "BETTER", 0)])
def test_compare_ends_with_its_verdict_line(
        candidate_value: float, verdict: str, code: int, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    base = write(tmp_path / "base" / "U-1" / "certificate.json", certificate(results=[
        result("x", 1.0, u_a=0.01, direction="higher"), result("y", 2.0, u_a=0.01)]))
    cand = write(tmp_path / "cand" / "U-1" / "certificate.json", certificate(results=[
        result("x", candidate_value, u_a=0.01, direction="higher"),
        result("y", 2.0, u_a=0.01)]))
    assert main(["compare", str(base), str(cand), "--json", str(tmp_path / "o.json"),
                 "--markdown", str(tmp_path / "o.md")]) == code
    last = capsys.readouterr().out.rstrip("\n").splitlines()[-1]
    assert last.startswith(f"VERDICT: {verdict}. "), last
    assert f"(exit {code})" in last
    assert json.loads((tmp_path / "o.json").read_text())["exit_code"] == code


# -- start-up: what loads ---------------------------------------------------------------------
PARSED_ONLY = [
    ["--help"], ["--version"], ["calibrate", "--help"], ["results", "spc", "--help"],
    ["compare", "--help"], ["diagnose", "--help"], ["simulate", "--help"],
    # parsed, not run (parse_args stops there)
    ["compare", "a", "b"], ["results", "units"], ["calibrate", "--drive", "sim"],
    ["diagnose", "rec.csv", "--json", "o.json"], ["simulate", "--duration", "9", "--out", "x"],
]


@pytest.mark.parametrize("argv", PARSED_ONLY, ids=[" ".join(a) for a in PARSED_ONLY])
def test_help_and_argument_parsing_load_no_subcommand_dependency(argv: list[str]) -> None:
    script = (
        "import argparse, sys\n"
        "original = argparse.ArgumentParser.parse_args\n"
        "def parse_only(self, args=None, namespace=None):\n"
        "    original(self, args, namespace)\n"
        "    raise SystemExit(0)\n"
        "argparse.ArgumentParser.parse_args = parse_only\n"
        "from hil.cli import main\n"
        "try:\n"
        f"    main({argv!r})\n"
        "except SystemExit:\n"
        "    pass\n"
        f"heavy = {HEAVY!r}\n"
        "print('LOADED', sorted({m.split('.')[0] for m in sys.modules} & set(heavy)))\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == "LOADED []", done.stdout[-2000:]


def test_simulate_loads_neither_the_store_nor_the_statistics(tmp_path: Path) -> None:
    script = (
        "import sys\n"
        "from hil.cli import main\n"
        f"assert main(['simulate', '--duration', '8', '--out', {str(tmp_path / 'r.csv')!r}]) == 0\n"
        "print('LOADED', sorted(m for m in ('sqlalchemy', 'scipy.stats', 'matplotlib', "
        "'pytest', 'alembic') if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == "LOADED []", done.stdout[-2000:]


def test_a_too_short_simulation_is_one_line_exit_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "--duration", "0.5", "--out", str(tmp_path / "r.csv")]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("gimbal-hil: error: --duration: ")
    assert not (tmp_path / "r.csv").exists()

