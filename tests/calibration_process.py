"""A calibration as an operator's process runs it, to be interrupted: ``gimbal-hil
calibrate`` in a subprocess, its console read as it comes, its log written to a file the
test watches for the moment to send a signal."""

from __future__ import annotations

import functools
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path


class RunningCalibration:
    """``gimbal-hil calibrate ARGS -- PYTEST_ARGS`` started in ``folder`` (no store, no
    documents, INFO log to ``folder/calibrate.log``); with ``sigint_ignored`` as a script's
    background job starts it (SIGINT ignored, as ``cmd &`` does without job control),
    otherwise with SIGINT at its default whatever this test process has."""

    def __init__(self, folder: Path, args: list[str], pytest_args: tuple[str, ...] = (),
                 *, sigint_ignored: bool = False) -> None:
        self.log_file = folder / "calibrate.log"
        command = [sys.executable, "-m", "hil.cli", "calibrate", *args, "--",
                   "--store", "off", "--no-documents", "-p", "no:cacheprovider",
                   "--log-file", str(self.log_file), "--log-file-level", "INFO",
                   *pytest_args]
        self.process = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"}, cwd=folder,
            preexec_fn=functools.partial(signal.signal, signal.SIGINT,
                                         signal.SIG_IGN if sigint_ignored else signal.SIG_DFL))
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.lines.append(line)

    @property
    def console(self) -> str:
        return "".join(self.lines)

    def wait_for_console(self, text: str, timeout_s: float = 240) -> None:
        """Until a console line holds ``text`` (a protocol's start line, say)."""
        deadline = time.monotonic() + timeout_s
        while not any(text in line for line in self.lines):
            assert time.monotonic() < deadline, f"no '{text}' in:\n{self.console}"
            assert self.process.poll() is None, f"ended before '{text}':\n{self.console}"
            time.sleep(0.02)

    def wait_for_log(self, pattern: str, *, offset: int = 0, timeout_s: float = 120) -> None:
        """Until the log, from byte ``offset`` on, matches ``pattern``."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.log_file.is_file():
                with self.log_file.open("rb") as stream:
                    stream.seek(offset)
                    if re.search(pattern, stream.read().decode("utf-8", "replace")):
                        return
            assert self.process.poll() is None, (
                f"ended before '{pattern}' was logged:\n{self.console}\n{self._log_tail()}")
            time.sleep(0.02)
        raise AssertionError(f"no '{pattern}' in {self.log_file} after {timeout_s} s:\n"
                             f"{self.console}\n{self._log_tail()}")

    def _log_tail(self, lines: int = 40) -> str:
        if not self.log_file.is_file():
            return "(no log)"
        text = self.log_file.read_text(encoding="utf-8", errors="replace")
        return "log, last lines:\n" + "\n".join(text.splitlines()[-lines:])

    def log_size(self) -> int:
        return self.log_file.stat().st_size if self.log_file.is_file() else 0

    def stop_with(self, signum: signal.Signals) -> int:
        """Send ``signum``; the exit code (the process killed if it does not end)."""
        self.process.send_signal(signum)
        return self.wait(120)

    def wait(self, timeout_s: float) -> int:
        """The exit code once the process ends (killed if it has not in ``timeout_s``),
        its console read to the end."""
        try:
            return self.process.wait(timeout_s)
        finally:
            if self.process.poll() is None:
                self.process.kill()
            self._reader.join(10)
