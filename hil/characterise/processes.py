"""``gimbal-hil`` commands run one after another, each in a process of its own that starts
without importing anything.

A calibration's process spends about 2 s importing numpy, scipy, numba's compiled kernel
and pytest before it moves the first sample: a population of 30 units pays a minute for it.
Here one server process imports all of that once (a multiprocessing *forkserver*); every
command is a fresh child forked from it, so each still runs alone (its own modules, globals,
signal handlers, working folder and environment, an exit code) as a new process would.

The command is found as a user's shell finds it: the ``gimbal-hil`` console script's entry
point.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import sys
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib.metadata import entry_points
from multiprocessing.context import ForkServerContext
from pathlib import Path

#: What the server imports once: a calibration's libraries (numba's BLAS check is what
#: loading the cached kernel costs, scipy.linalg) and the harness's layers.
PRELOAD = ("numpy", "scipy.linalg", "scipy.signal", "scipy.optimize", "numba",
           "numba.np.arraymath", "pytest", "plant_sim.kernel", "hil.plugin",
           "hil.calibration_session")
#: The server's hash seed, so that every child has the same one (and a population the
#: same results whichever process ran which unit).
HASH_SEED = "0"


@dataclass(frozen=True, slots=True)
class Finished:
    """How a command ended: its exit code and what it wrote to each stream."""

    returncode: int
    stdout: str
    stderr: str


_context: ForkServerContext | None = None


def _server() -> ForkServerContext:
    global _context
    if _context is None:
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(list(PRELOAD))
        previous = os.environ.get("PYTHONHASHSEED")
        os.environ["PYTHONHASHSEED"] = HASH_SEED  # read once, as the server starts
        try:
            from multiprocessing import forkserver

            forkserver.ensure_running()
        finally:
            if previous is None:
                del os.environ["PYTHONHASHSEED"]
            else:
                os.environ["PYTHONHASHSEED"] = previous
        _context = context
    return _context


def run_command(argv: Sequence[str], *, cwd: Path | None = None,
                env: Mapping[str, str] | None = None, timeout_s: float | None = None
                ) -> Finished:
    """Run ``gimbal-hil ARGV`` in a child of the server and wait for it.

    Parameters
    ----------
    argv : sequence of str
        The command's arguments (without ``gimbal-hil``).
    cwd : Path, optional
        Its working folder (default: this process's).
    env : mapping, optional
        Its environment (default: this process's). Variables that act only as Python
        starts (``PYTHONPATH``, ``PYTHONHASHSEED``) have no effect: the child is forked.
    timeout_s : float, optional
        Longest wait; then the child is killed.

    Returns
    -------
    Finished

    Raises
    ------
    TimeoutError
        The command ran longer than ``timeout_s`` (it was killed).
    """
    context = _server()
    with tempfile.TemporaryDirectory(prefix="gimbal-hil-command-") as folder:
        streams = (Path(folder) / "stdout.txt", Path(folder) / "stderr.txt")
        child = context.Process(target=_child, args=(
            list(argv), str(cwd or Path.cwd()), dict(os.environ if env is None else env),
            tuple(str(s) for s in streams)))
        child.start()
        child.join(timeout_s)
        if child.exitcode is None:
            child.kill()
            child.join()
            raise TimeoutError(f"gimbal-hil {' '.join(argv)}: still running after "
                               f"{timeout_s} s (killed)")
        stdout, stderr = (s.read_text(encoding="utf-8", errors="replace") if s.is_file()
                          else "" for s in streams)
    return Finished(returncode=child.exitcode, stdout=stdout, stderr=stderr)


def _child(argv: list[str], cwd: str, env: dict[str, str], streams: tuple[str, str]
           ) -> None:
    """The forked process: stdout and stderr to the files ``streams``, then the command,
    then its exit code."""
    for descriptor, name in enumerate(streams, start=1):
        stream = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        os.dup2(stream, descriptor)
        os.close(stream)
    sys.stdout = open(1, "w", encoding="utf-8", closefd=False, buffering=1)  # noqa: SIM115
    sys.stderr = open(2, "w", encoding="utf-8", closefd=False, buffering=1)  # noqa: SIM115
    os.chdir(cwd)
    os.environ.clear()
    os.environ.update(env)
    sys.argv = ["gimbal-hil", *argv]
    (command,) = entry_points(group="console_scripts", name="gimbal-hil")
    try:
        code = command.load()(argv)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(int(code or 0))
