"""What the operator's console shows: which protocol runs, n of N, the time left, and a
large PASS / MARGINAL / FAIL at the end. Pure text; the pytest layer writes it."""

from __future__ import annotations

from collections.abc import Mapping

from hil.report.view import BANNER

#: Block letters, five rows each (only the letters the banners use).
LETTERS: dict[str, tuple[str, ...]] = {
    "A": (" ███ ", "█   █", "█████", "█   █", "█   █"),
    "C": (" ████", "█    ", "█    ", "█    ", " ████"),
    "D": ("████ ", "█   █", "█   █", "█   █", "████ "),
    "E": ("█████", "█    ", "████ ", "█    ", "█████"),
    "F": ("█████", "█    ", "████ ", "█    ", "█    "),
    "G": (" ████", "█    ", "█  ██", "█   █", " ████"),
    "I": ("█████", "  █  ", "  █  ", "  █  ", "█████"),
    "L": ("█    ", "█    ", "█    ", "█    ", "█████"),
    "M": ("█   █", "██ ██", "█ █ █", "█   █", "█   █"),
    "N": ("█   █", "██  █", "█ █ █", "█  ██", "█   █"),
    "O": (" ███ ", "█   █", "█   █", "█   █", " ███ "),
    "P": ("████ ", "█   █", "████ ", "█    ", "█    "),
    "R": ("████ ", "█   █", "████ ", "█  █ ", "█   █"),
    "S": (" ████", "█    ", " ███ ", "    █", "████ "),
    "T": ("█████", "  █  ", "  █  ", "  █  ", "  █  "),
    "U": ("█   █", "█   █", "█   █", "█   █", " ███ "),
    " ": ("  ", "  ", "  ", "  ", "  "),
}


def block_letters(word: str) -> list[str]:
    """``word`` in five rows of block letters.

    Parameters
    ----------
    word : str
        The text; characters without a glyph are written as themselves.

    Returns
    -------
    list of str
        Five rows.
    """
    glyphs = [LETTERS.get(c, (c,) * 5) for c in word.upper()]
    return [" ".join(g[row] for g in glyphs).rstrip() for row in range(5)]


def outcome_banner(outcome: str, *, aborted: bool = False) -> list[str]:
    """The overall outcome as a boxed block-letter banner with its meaning under it.

    Parameters
    ----------
    outcome : str
        ``PASS``, ``MARGINAL``, ``FAIL`` or ``ERROR`` (the certificate's ``outcome``).
    aborted : bool
        The run was interrupted (said under the word).

    Returns
    -------
    list of str
        The banner's lines.
    """
    word, meaning = BANNER.get(outcome, (outcome, ""))
    if aborted:
        meaning = "the run was ABORTED: " + meaning
    rows = block_letters("ERROR" if outcome == "ERROR" else word)
    if outcome == "ERROR":
        rows.append("")
        rows.append(word)
    rows += ["", meaning]
    width = max(len(r) for r in rows) + 4
    return ["┏" + "━" * width + "┓",
            *(f"┃  {r:<{width - 4}}  ┃" for r in rows),
            "┗" + "━" * width + "┛"]


def protocol_start(name: str, plan: Mapping[str, float], *, done_motion_s: float,
                   done_wall_s: float) -> str:
    """The line written when protocol ``name`` starts.

    Parameters
    ----------
    name : str
        The protocol starting.
    plan : mapping
        Planned motion per protocol in run order (:func:`hil.suite.plan.planned_motion_s`).
    done_motion_s, done_wall_s : float
        Motion commanded and wall time spent by the protocols before it: their ratio is
        this drive's pace (a simulator runs faster than real time, a real axis does not).

    Returns
    -------
    str
        ``"▶ protocol 2 of 6: gravity_cable (30.7 s of motion); 82.0 s of motion left,
        about 6 s at this drive's pace"``.
    """
    names = list(plan)
    index = names.index(name) + 1 if name in plan else len(names) + 1
    total = max(len(names), index)
    left = sum(plan[n] for n in names[index - 1:]) if name in plan else 0.0
    line = f"▶ protocol {index} of {total}: {name} ({plan.get(name, 0.0):.1f} s of motion)"
    line += f"; {left:.1f} s of motion left"
    if done_motion_s > 0 and done_wall_s > 0:
        line += f", about {left * done_wall_s / done_motion_s:.0f} s at this drive's pace"
    return line
