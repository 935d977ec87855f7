"""Careless and hostile input, as issue 26 tried it: each gets its one-line error and exit
code, no traceback reaches the user, and nothing is written where a refusal happened.

The cases need no motion (each stops before the first excitation, or is a command that
moves nothing); what needs motion has its own tests (signals, the motion monitor, the unit
lock, integrity, the complete run). docs/robustness.md lists every input of the issue with
where it is handled.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from hil.characterise.processes import run_command
from hil.profile import builtin_profile_path

DEMO = builtin_profile_path().read_text(encoding="utf-8")
SHARED = Path(__file__).resolve().parents[2] / "shared"
EXAMPLE = SHARED / "recordings" / "example_00.csv.gz"


def _without_plant(text: str) -> str:
    head, rest = text.split("[plant]\n", 1)
    return head + rest[rest.index("\n[protocols."):]


def _recording(path: Path, time_scale: float = 1.0, moving: bool = True) -> None:
    time_s = np.arange(2000) / 1000.0
    position = 0.1 * time_s if moving else np.zeros_like(time_s)
    lines = ["time_s,velocity_cmd_rad_s,position_rad,velocity_rad_s,torque_nm"]
    lines += [f"{t * time_scale:.6f},0.1,{p:.6f},0.1,{0.02 + 0.001 * np.sin(i):.6f}"
              for i, (t, p) in enumerate(zip(time_s, position, strict=True))]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


@dataclass(frozen=True)
class Case:
    args: tuple[str, ...]
    exit_code: int
    says: str  # in the one line the user reads
    files: dict[str, str] = field(default_factory=dict)  # name → text, made in the folder
    setup: Callable[[Path], None] | None = None


def _calibrate(*args: str) -> tuple[str, ...]:
    return ("calibrate", "--drive", "sim", "--out", "out", *args)


CASES: dict[str, Case] = {
    "a misspelt protocol table": Case(
        _calibrate("--profile", "p.toml"), 4, "no such protocol (did you mean 'stribeck'?)",
        {"p.toml": DEMO.replace("[protocols.stribeck]", "[protocols.stribek]")}),
    "a misspelt measurement table": Case(
        _calibrate("--profile", "p.toml"), 4, "did you mean 'static_friction_nm'?",
        {"p.toml": DEMO.replace("[measurements.static_friction_nm]",
                                "[measurements.static_friction_mn]")}),
    "a misspelt protocol setting": Case(
        _calibrate("--profile", "p.toml"), 4, "unknown setting 'speeds_rad_sx'",
        {"p.toml": DEMO.replace("[protocols.stribeck]",
                                "[protocols.stribeck]\nspeeds_rad_sx = [0.1]")}),
    "a profile with a UTF-8 byte-order mark": Case(
        _calibrate("--profile", "p.toml", "--", "--collect-only", "-q"), 0, "test_stribeck",
        {"p.toml": "\ufeff" + DEMO}),
    "the simulator without a [plant] table": Case(
        _calibrate("--profile", "p.toml"), 4, "has none", {"p.toml": _without_plant(DEMO)}),
    "a unit serial with a slash": Case(
        _calibrate("--unit-serial", "a/b"), 4, "'a/b' is not a unit serial"),
    "a blank unit serial": Case(_calibrate("--unit-serial", ""), 2, "cannot be blank"),
    "a real drive without a serial": Case(
        ("calibrate", "--drive", "canopen", "--out", "out"), 2, "give its --unit-serial"),
    "a method-bias map that is not TOML": Case(
        _calibrate("--", "--method-bias", "bias.toml"), 4, "bias.toml: not valid TOML",
        {"bias.toml": "garbage\n"}),
    "simulate --duration 1": Case(
        ("simulate", "--duration", "1", "--out", "r.csv"), 2, "at least 8 s"),
    "simulate --duration nan": Case(
        ("simulate", "--duration", "nan", "--out", "r.csv"), 2, "--duration: must be"),
    "simulate --duration 1e9": Case(
        ("simulate", "--duration", "1e9", "--out", "r.csv"), 2, "from 8 to 7200"),
    "simulate --seed -1": Case(
        ("simulate", "--duration", "10", "--seed", "-1", "--out", "r.csv"), 2,
        "must be 0 or more"),
    "a command file of two samples": Case(
        ("simulate", "--command", "c.csv", "--out", "r.csv"), 2, "at least 100 are needed",
        {"c.csv": "time_s,velocity_cmd_rad_s\n0,0\n1000000,0.1\n"}),
    "diagnose --json under a file": Case(
        ("diagnose", str(EXAMPLE), "--json", "f/x.json"), 2, "is a file", {"f": "a file\n"}),
    "diagnose --plots naming a file": Case(
        ("diagnose", str(EXAMPLE), "--json", "d.json", "--plots", "f"), 2, "cannot write",
        {"f": "a file\n"}),
    "a recording in milliseconds": Case(
        ("diagnose", "ms.csv", "--json", "d.json"), 2, "is the time column in milliseconds?",
        setup=lambda d: _recording(d / "ms.csv", time_scale=1000.0)),
    "a recording of an axis at rest": Case(
        ("diagnose", "rest.csv", "--json", "d.json"), 2, "the axis never moves",
        setup=lambda d: _recording(d / "rest.csv", moving=False)),
    "a recording with its position in degrees": Case(
        ("diagnose", "deg.csv", "--json", "d.json"), 2, "position_rad looks like degrees",
        setup=lambda d: _in_degrees(EXAMPLE, d / "deg.csv")),
    "a recording with a byte-order mark": Case(
        ("diagnose", "bom.csv", "--json", "d.json"), 0, "base fit",
        setup=lambda d: (d / "bom.csv").write_text(
            "\ufeff" + "\n".join(_lines_of(EXAMPLE)) + "\n", encoding="utf-8")),
    "a results command on a folder without a store": Case(
        ("results", "units", "--out", "nowhere"), 2, "no results store"),
}


def _in_degrees(source: Path, target: Path) -> None:
    lines = _lines_of(source)
    column = lines[0].split(",").index("position_rad")
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        cells[column] = repr(math.degrees(float(cells[column])))
        out.append(",".join(cells))
    target.write_text("\n".join(out) + "\n", encoding="utf-8")


def _lines_of(path: Path) -> list[str]:
    import gzip

    return gzip.decompress(path.read_bytes()).decode("utf-8").splitlines()


@pytest.mark.parametrize("name", sorted(CASES))
def test_careless_input_gets_one_line_and_no_traceback(tmp_path: Path, name: str) -> None:
    case = CASES[name]
    if str(EXAMPLE) in case.args and not EXAMPLE.is_file():
        pytest.skip("shared recordings not present")
    for file, text in case.files.items():
        (tmp_path / file).write_text(text, encoding="utf-8")
    if case.setup is not None:
        case.setup(tmp_path)
    done = run_command(case.args, cwd=tmp_path, timeout_s=600)
    text = done.stdout + done.stderr
    assert done.returncode == case.exit_code, text[-3000:]
    assert "Traceback" not in text, text[-3000:]
    said = [line for line in text.splitlines() if case.says in line]
    assert len(said) == 1, text[-3000:]
    if case.exit_code != 0:
        assert not (tmp_path / "out").exists(), "a refused run wrote into --out"
        assert not (tmp_path / "nowhere").exists(), "a read command made a store"


def test_a_bug_is_one_line_for_the_operator_and_a_traceback_with_verbose(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:
    import hil.cli

    def broken(_args: object) -> int:
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(hil.cli, "_simulate", broken)
    assert hil.cli.main(["simulate", "--duration", "10", "--out", "r.csv"]) == 3
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("gimbal-hil: internal error: ZeroDivisionError: division by zero")
    with pytest.raises(ZeroDivisionError):
        hil.cli.main(["-v", "simulate", "--duration", "10", "--out", "r.csv"])
