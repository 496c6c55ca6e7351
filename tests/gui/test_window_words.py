"""The window's words for run_protocol's flags (:mod:`daq.gui.window_words`): before, the window
told its user to "continue it with --resume FILE" or "write a new file (--out NAME)"."""

from __future__ import annotations

from daq.gui.window_words import in_window_words


def test_the_flags_become_the_windows_controls() -> None:
    line = (
        "--out: a.h5 exists already (a run left aborted): continue it with --resume a.h5, or "
        "write a new file (--out a_2.h5)"
    )
    assert in_window_words(line) == (
        "Output: a.h5 exists already (a run left aborted): continue it with Resume file… "
        "(a.h5), or write a new file (Output: a_2.h5)"
    )
    assert in_window_words("fix the bench, then --resume /r/a.h5") == (
        "fix the bench, then Resume file… (/r/a.h5)"
    )
    assert in_window_words("run complete: 6 points") == "run complete: 6 points"
