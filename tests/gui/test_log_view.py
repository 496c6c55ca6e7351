"""The window's log view (:class:`daq.gui.panels.LogView`): its lines are stamped HH:MM:SS
only, so over a week-long run the log must also say which day each line is from."""

from __future__ import annotations

import datetime as dt
from typing import Any

from daq.gui.panels import LogView

CET = dt.timezone(dt.timedelta(hours=1), "CET")


class Clock:
    """A settable clock for the view (local time with its zone, as the window's)."""

    def __init__(self, when: dt.datetime) -> None:
        self.when = when

    def __call__(self) -> dt.datetime:
        return self.when


def test_a_new_log_begins_with_a_line_naming_todays_date(qtbot: Any) -> None:
    """The first line of a new log names the date, local time: before, a line read
    "15:10:11 info    ..." and nothing in the log said which day it was."""
    view = LogView()
    qtbot.addWidget(view)
    before = dt.datetime.now().astimezone().date()
    view.add("connected")
    after = dt.datetime.now().astimezone().date()
    first, second = view.toPlainText().splitlines()
    assert any(f"— {d:%Y-%m-%d} (" in first for d in {before, after}), first
    assert second.endswith("info    connected")
    assert view.lines == [second]  # the logged lines: the heading is the view's alone


def test_a_line_after_midnight_is_preceded_by_the_new_date(qtbot: Any) -> None:
    """Past midnight the next line is preceded by a line naming the new day, so a line of a
    week-long run is not read as one from the day before; lines of the same day get none."""
    clock = Clock(dt.datetime(2026, 11, 27, 23, 59, 58, tzinfo=CET))
    view = LogView(now=clock)
    qtbot.addWidget(view)
    view.add("point 17 done")
    clock.when = dt.datetime(2026, 11, 27, 23, 59, 59, tzinfo=CET)
    view.add("point 18 done")
    clock.when = dt.datetime(2026, 11, 28, 0, 0, 3, tzinfo=CET)
    view.add("point 19 done", "warning")
    assert view.toPlainText().splitlines() == [
        "— 2026-11-27 (CET) —",
        "23:59:58 info    point 17 done",
        "23:59:59 info    point 18 done",
        "— 2026-11-28 (CET) —",
        "00:00:03 warning point 19 done",
    ]


def test_warnings_and_errors_keep_their_spaces(qtbot: Any) -> None:
    """A warning or an error is drawn in colour (rich text), where runs of spaces collapse:
    "00:00:03 error   cannot read the stage" was shown as "00:00:03 error cannot read the
    stage", its message closer to the stamp than the other lines' (and a message's own double
    spaces were lost)."""
    clock = Clock(dt.datetime(2026, 11, 28, 0, 0, 3, tzinfo=CET))
    view = LogView(now=clock)
    qtbot.addWidget(view)
    view.add("point 19 done")
    view.add("cannot read the stage", "error")
    view.add("stage  slow", "warning")
    assert (
        view.toPlainText().splitlines()[1:]
        == view.lines
        == [
            "00:00:03 info    point 19 done",
            "00:00:03 error   cannot read the stage",
            "00:00:03 warning stage  slow",
        ]
    )
