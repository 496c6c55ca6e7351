"""The live views' redraw pace (:mod:`daq.gui.redraw_pace`): the fastest while the window has
time, slower while drawing takes most of it. Before, a fixed 100 ms pace kept the window
drawing most of the time on a fast bench (2,480 simulated points: 47-58 s in the window
against 18 s from the command line; now 25-28 s)."""

from __future__ import annotations

import time
from typing import Any

from daq.gui.main_window import MainWindow
from daq.gui.redraw_pace import FASTEST_MS, SLOWEST_MS, RedrawPace, next_interval_ms

from .conftest import SMOKE


def test_the_pace_doubles_when_busy_and_halves_when_idle_within_its_bounds() -> None:
    assert next_interval_ms(100, 0.9) == 200
    assert next_interval_ms(800, 0.9) == SLOWEST_MS
    assert next_interval_ms(SLOWEST_MS, 1.0) == SLOWEST_MS
    assert next_interval_ms(400, 0.3) == 400  # between the thresholds: unchanged
    assert next_interval_ms(400, 0.1) == 200
    assert next_interval_ms(FASTEST_MS, 0.0) == FASTEST_MS


def test_the_pace_follows_the_share_of_cpu_time_between_ticks() -> None:
    clock = {"cpu": 0.0, "wall": 0.0}
    pace = RedrawPace(cpu_s=lambda: clock["cpu"], wall_s=lambda: clock["wall"])

    def interval(cpu: float, wall: float) -> int:
        clock["cpu"] += cpu
        clock["wall"] += wall
        return pace.tick()

    assert interval(0.3, 0.4) == 200  # a 300 ms frame after a 100 ms wait: busy 0.75
    assert interval(0.3, 0.5) == 400  # 0.6
    assert interval(0.3, 0.7) == 400  # 0.43: steady
    assert interval(0.0, 0.4) == 200  # nothing drawn
    assert interval(0.0, 0.2) == FASTEST_MS


def test_the_pace_reads_this_threads_cpu_clock_by_default() -> None:
    pace = RedrawPace()
    assert pace._cpu_s is time.thread_time and pace._wall_s is time.monotonic


class _Pace:
    """The pace of a window whose drawing takes most of its time."""

    def tick(self) -> int:
        return 4 * FASTEST_MS


def test_the_window_redraws_at_its_pace(qtbot: Any) -> None:
    win = MainWindow(None, SMOKE)
    qtbot.addWidget(win)
    drawn: list[float] = []
    win.views.redraw = lambda live: drawn.append(time.monotonic())  # type: ignore[method-assign]
    win._pace = _Pace()  # type: ignore[assignment]
    t_end = time.monotonic() + 2.0
    while time.monotonic() < t_end:
        win._dirty = True  # points keep arriving
        qtbot.wait(10)
    assert win._redraw_timer.interval() == 4 * FASTEST_MS
    assert 3 <= len(drawn) <= 7  # every 400 ms after the first 100 (at a fixed pace: 20)
