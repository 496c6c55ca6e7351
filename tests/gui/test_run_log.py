"""The run log the window holds for each run (``RUN.log`` beside ``RUN.h5``,
:func:`daq.logsetup.hold_run_log`): what a physicist reads after the run."""

from __future__ import annotations

import datetime as dt
from pathlib import Path
from typing import Any

from daq.gui.main_window import MainWindow
from protocols.runfile import read_run

from .conftest import silent_generator, unsafe_window


def _lines(log: Path) -> list[tuple[dt.datetime, str, str]]:
    """(time stamp, level, message) of each line of a run log; every line has an ISO 8601
    stamp with its zone, a level and a logger name."""
    out = []
    for line in log.read_text(encoding="utf-8").splitlines():
        stamp, level, rest = line.split(maxsplit=2)
        when = dt.datetime.fromisoformat(stamp)
        assert when.tzinfo is not None, line
        name, message = rest.split(": ", 1)
        assert name.startswith("biafc."), line
        out.append((when, level, message))
    return out


def _check(log: Path, run: Path, win: MainWindow) -> list[str]:
    """The run's lines in time order, from the window's 'starting' to the last line, which is
    the window's last line and begins with the file's ``outcome``; its messages."""
    lines = _lines(log)
    stamps = [w for w, _, _ in lines]
    assert stamps == sorted(stamps)
    messages = [m for _, _, m in lines]
    assert messages[0].startswith("starting run -> ") and messages[0].endswith(run.name)
    assert messages[1] == "run started: protocol 'smoke', 6 points"
    outcome = str(read_run(run).attrs["outcome"])
    assert messages[-1].startswith(outcome), (messages[-1], outcome)
    assert win.log_view.lines[-1].endswith(messages[-1])  # the window's last line: the same
    assert sum(m.startswith("starting run") for m in messages) == 1
    assert sum(m.startswith("run started") for m in messages) == 1
    return messages


def test_each_run_log_holds_its_own_run_in_order_ending_with_its_outcome(
    qtbot: Any, tmp_path: Path
) -> None:
    """A run that ends UNSAFE, then a complete one in the same window: each log ends with its
    own run's outcome (the complete run's log ended with the window's note that the earlier
    UNSAFE was taken down, after the run's outcome), and neither has the other's lines."""

    unsafe, good = tmp_path / "u.h5", tmp_path / "ok.h5"
    win = unsafe_window(qtbot, unsafe, silent_generator())  # the generator goes silent
    first = _check(unsafe.with_suffix(".log"), unsafe, win)
    assert first[-1].startswith("run UNSAFE") and "SWITCH OFF BY HAND" in first[-1]
    before = unsafe.with_suffix(".log").read_text(encoding="utf-8")

    win.instruments.world.faults.clear()  # the generator answers again
    qtbot.waitUntil(lambda: win.run_panel.start_button.isEnabled(), timeout=10_000)
    win.run_panel.out_edit.setText(str(good))
    with qtbot.waitSignal(win.run_finished, timeout=60_000) as blocker:
        win.run_panel.start_button.click()
    assert blocker.args == ["complete"]
    second = _check(good.with_suffix(".log"), good, win)
    assert second[-1].startswith("complete: 6 points")
    assert second[-2].startswith("the earlier run's UNSAFE is taken down")  # before the end
    assert not any("u.h5" in m or "SWITCH OFF" in m or "run UNSAFE" in m for m in second)
    qtbot.wait(300)  # the read of the instruments after the run, and its lines
    assert unsafe.with_suffix(".log").read_text(encoding="utf-8") == before
    assert _check(good.with_suffix(".log"), good, win) == second  # nothing after the end
