"""A line written for the command line, as the bench window says it: ``run_protocol``'s flags
become the window's controls (``--resume FILE`` the *Resume file…* button, ``--out`` the
*Output* field). The engine and the request check write one text for both; before, the window
told its user to type flags it has no place for."""

from __future__ import annotations

import re

__all__ = ["in_window_words"]

_RULES: tuple[tuple[re.Pattern[str], str], ...] = (
    (re.compile(r"(?:run_protocol )?--resume ([^\s,;)]+)"), r"Resume file… (\1)"),
    (re.compile(r"--resume:"), "Resume file:"),
    (re.compile(r"\(--out (\S+)\)"), r"(Output: \1)"),
    (re.compile(r"--out:"), "Output:"),
)


def in_window_words(text: str) -> str:
    """``text`` with ``run_protocol``'s flags named as the window's controls."""
    for pattern, repl in _RULES:
        text = pattern.sub(repl, text)
    return text
