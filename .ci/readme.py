"""The README's command blocks, run as written from the repository root (CI's check that
the README tells the truth).

Every ```bash block runs in one bash process (its `export`s hold for its later lines), in
the order of the README; a line ending in ``# exit N`` must exit N, every other line 0, and
the block stops at the first that does not. A block the README marks with an HTML comment
``<!-- not run in CI: REASON -->`` on the line before it is left out, and said so. A plain
``` block right after a run block is that block's output excerpt: each of its lines,
numbers and dates masked, must appear in what the block printed (same words, columns,
units and verdicts; values may differ from seed to seed); ``<word>`` in an excerpt stands
for any one word (the station's host name).

``run --rest`` runs two blocks at a time (each writes files of its own), each block's
output printed whole, in the README's order; a block marked ``<!-- CI: after the blocks
above -->`` (it reads what they wrote) starts when every block before it has ended.

    python .ci/readme.py list            the blocks, numbered, and which run
    python .ci/readme.py run N [N ...]   run these blocks (1-based)
    python .ci/readme.py run --rest      every run block but the first two (the set-up)
    python .ci/readme.py run --rest --after REGEX
                                         the same, once a process whose command line
                                         matches REGEX runs (read from /proc: a fresh
                                         machine may have no pgrep); not at all if the
                                         process that started this one ends first
    python .ci/readme.py run --rest --after REGEX --pause-while REGEX
                                         the same, and while a process matching the second
                                         REGEX runs its blocks are stopped (SIGSTOP to each
                                         block's process group, SIGCONT after) and none
                                         starts: tests that time a field bus against the
                                         wall clock run alone, as the README says
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SKIP = re.compile(r"<!--\s*not run in CI:\s*(?P<reason>.+?)\s*-->")
AFTER = re.compile(r"<!--\s*CI: after the blocks above\b.*?-->")
AT_ONCE = 2  # blocks run at a time by ``run --rest`` (CI's runner has two cores)
EXIT = re.compile(r"#\s*exit (?P<code>\d+)\b")
NUMBER = re.compile(r"[-+]?\d[\d:.\-T]*(?:e[-+]?\d+)?")
SETUP_BLOCKS = 2


class Pauser:
    """Stops the running blocks while a process matching ``pattern`` runs, and lets none
    start (a block is its own process group: bash, and every process its commands start)."""

    def __init__(self, pattern: re.Pattern[str] | None, poll_s: float = 0.5) -> None:
        self.pattern, self.poll_s = pattern, poll_s
        self.groups: set[int] = set()
        self.lock = threading.Lock()
        self.free = threading.Event()
        self.free.set()
        self.done = threading.Event()
        self.paused_s = 0.0

    def __enter__(self) -> Pauser:
        if self.pattern is not None:
            threading.Thread(target=self._watch, name="pause-while", daemon=True).start()
        return self

    def __exit__(self, *_: object) -> None:
        self.done.set()
        self._signal(signal.SIGCONT)  # never leave a block stopped

    def start(self, command: list[str]) -> subprocess.Popen[str]:
        """``command`` in a process group of its own, once nothing asks for a pause."""
        while True:
            self.free.wait()
            with self.lock:
                if self.free.is_set():
                    process = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE,
                                               stderr=subprocess.STDOUT, text=True,
                                               start_new_session=True)
                    self.groups.add(process.pid)
                    return process

    def ended(self, process: subprocess.Popen[str]) -> None:
        with self.lock:
            self.groups.discard(process.pid)

    def _signal(self, number: signal.Signals) -> None:
        with self.lock:
            for group in self.groups:
                with contextlib.suppress(ProcessLookupError):  # the block ended meanwhile
                    os.killpg(group, number)

    def _watch(self) -> None:
        assert self.pattern is not None
        since = 0.0
        while not self.done.wait(self.poll_s):
            asked = process_running(self.pattern)
            if asked and self.free.is_set():
                with self.lock:
                    self.free.clear()
                self._signal(signal.SIGSTOP)
                since = time.monotonic()
                print("README blocks: stopped while the realtime tests run", flush=True)
            elif not asked and not self.free.is_set():
                self._signal(signal.SIGCONT)
                self.free.set()
                self.paused_s += time.monotonic() - since
                print(f"README blocks: go on after {self.paused_s:.0f} s stopped", flush=True)


NO_PAUSE = Pauser(None)


@dataclass(frozen=True)
class Block:
    number: int
    line: int
    commands: tuple[str, ...]
    skip_reason: str | None
    excerpt: tuple[str, ...]
    after_the_blocks_above: bool = False


def blocks(text: str) -> list[Block]:
    lines = text.splitlines()
    found: list[Block] = []
    i = 0
    while i < len(lines):
        if lines[i].strip() != "```bash":
            i += 1
            continue
        start = i
        end = lines.index("```", i + 1)
        commands = tuple(x for x in lines[i + 1:end]
                         if x.strip() and not x.lstrip().startswith("#"))
        previous = next((x for x in reversed(lines[:start]) if x.strip()), "")
        skip = SKIP.search(previous)
        excerpt: tuple[str, ...] = ()
        after = end + 1
        while after < len(lines) and not lines[after].strip():
            after += 1
        if after < len(lines) and lines[after].strip() == "```":
            close = lines.index("```", after + 1)
            excerpt = tuple(x for x in lines[after + 1:close] if x.strip())
            end = close
        found.append(Block(len(found) + 1, start + 1, commands,
                           skip.group("reason") if skip else None, excerpt,
                           AFTER.search(previous) is not None))
        i = end + 1
    return found


def skeleton(line: str) -> str:
    """A line with its numbers and dates masked and its spacing folded."""
    return " ".join(NUMBER.sub("#", line).split())


def excerpt_pattern(line: str) -> re.Pattern[str]:
    """An excerpt line's skeleton as a pattern; ``<word>`` matches any one word."""
    return re.compile("^" + re.sub(r"<\w+>", lambda _: r"\S+", re.escape(skeleton(line))) + "$")


def script(block: Block) -> str:
    """The block as one bash script that checks each line's exit status and says how long
    each line took (whole seconds)."""
    parts = []
    for command in block.commands:
        match = EXIT.search(command)
        expected = int(match.group("code")) if match else 0
        quoted = command.replace("'", "'\\''")
        parts.append(f"printf '%s\\n' '$ {quoted}'\n__t=$SECONDS\n{command}\n__rc=$?\n"
                     f"echo \"[README.md:{block.line}: $((SECONDS - __t)) s]\"\n"
                     f"if [ $__rc -ne {expected} ]; then echo \"README.md:{block.line}: "
                     f"exited $__rc, expected {expected}\" >&2; exit 1; fi")
    return "\n".join(parts) + "\n"


def run(block: Block, *, stream: bool = True,
        pauser: Pauser = NO_PAUSE) -> tuple[list[str], list[str]]:
    """Run ``block`` (its output streamed as it comes, or only kept); what it printed and
    the problems found."""
    process = pauser.start(["bash", "-o", "pipefail", "-c", script(block)])
    assert process.stdout is not None
    printed = []
    for line in process.stdout:
        if stream:
            sys.stdout.write(line)
            sys.stdout.flush()
        printed.append(line.rstrip("\n"))
    returncode = process.wait()
    pauser.ended(process)
    problems = [] if returncode == 0 else [
        line for line in printed if line.startswith(f"README.md:{block.line}: exited")
    ] or [f"README.md:{block.line}: block exited {returncode}"]
    shown = [skeleton(x) for x in printed]
    for line in block.excerpt:
        if line.strip() in ("…", "...") or line.lstrip().startswith("… ("):
            continue
        pattern = excerpt_pattern(line)
        if not any(pattern.match(x) for x in shown):
            problems.append(f"README.md:{block.line}: output excerpt line not printed "
                            f"(numbers masked): {line.strip()[:120]}")
    return printed, problems


def run_at_once(chosen: list[Block], pauser: Pauser = NO_PAUSE) -> list[str]:
    """Run ``chosen`` :data:`AT_ONCE` at a time (a block marked to run after the blocks
    above waits for them); each block's output printed whole, in order; the problems."""
    problems: list[str] = []
    with ThreadPoolExecutor(max_workers=AT_ONCE) as pool:
        started: list[Future[tuple[list[str], list[str]]]] = []
        for block in chosen:
            if block.after_the_blocks_above:
                wait(started)
            started.append(pool.submit(run, block, stream=False, pauser=pauser))
        for future in started:
            printed, found = future.result()
            print("\n".join(printed), flush=True)
            problems += found
    return problems


def process_running(pattern: re.Pattern[str]) -> bool:
    """Whether a process's command line (its arguments joined by spaces) matches
    ``pattern`` (read from /proc: a fresh machine may have no pgrep)."""
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            words = cmdline.read_bytes().split(b"\0")
        except OSError:  # ended while read
            continue
        if pattern.search(" ".join(w.decode("utf-8", "replace") for w in words if w)):
            return True
    return False


def wait_for_process(pattern: re.Pattern[str], poll_s: float = 1.0) -> bool:
    """Until a process matching ``pattern`` runs: ``True``; ``False`` when this process's
    parent ends first."""
    parent = os.getppid()
    while os.getppid() == parent:
        if process_running(pattern):
            return True
        time.sleep(poll_s)
    return False


def main(argv: list[str]) -> int:
    found = blocks((ROOT / "README.md").read_text(encoding="utf-8"))
    if not argv or argv[0] == "list":
        for block in found:
            state = f"not run: {block.skip_reason}" if block.skip_reason else "run"
            print(f"{block.number:>2}  README.md:{block.line:<4} {state}  "
                  f"{len(block.commands)} command(s), {len(block.excerpt)} excerpt line(s)")
        return 0
    if argv[0] != "run" or len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    pause_while = None
    if argv[-2:-1] == ["--pause-while"]:
        pause_while, argv = re.compile(argv[-1]), argv[:-2]
    if argv[1:3] == ["--rest", "--after"] and len(argv) == 4:
        if not wait_for_process(re.compile(argv[3])):
            print("README blocks: not run, the script that started them ended first",
                  file=sys.stderr)
            return 1
        argv = argv[:2]
    if argv[1:] == ["--rest"]:
        chosen = [b for b in found[SETUP_BLOCKS:] if b.skip_reason is None]
        for block in found[SETUP_BLOCKS:]:
            if block.skip_reason:
                print(f"README.md:{block.line}: not run in CI: {block.skip_reason}")
    else:
        chosen = [found[int(n) - 1] for n in argv[1:]]
    with Pauser(pause_while) as pauser:
        problems = (run_at_once(chosen, pauser) if argv[1:] == ["--rest"]
                    else [p for block in chosen for p in run(block, pauser=pauser)[1]])
    for problem in problems:
        print(problem, file=sys.stderr)
    print(f"README blocks: {len(chosen)} run, {len(problems)} problem(s)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
