"""How often the bench window redraws its live views: every :data:`FASTEST_MS` while its thread
has time, less often while drawing takes most of it.

Drawing the five views costs tens of milliseconds a frame (pyqtgraph's axes alone: about 8 ms
each on the offscreen platform). On a bench whose points come faster than the window can draw
them (the simulated bench runs 2,480 points in 18 s from the command line), a fixed 100 ms
redraw kept the window's thread drawing most of the time, and the run took 47-58 s in the
window. The pace now follows the share of the window thread's CPU time since the last tick:
above :data:`BUSY_HIGH` the interval doubles (up to :data:`SLOWEST_MS`), below
:data:`BUSY_LOW` it halves (down to :data:`FASTEST_MS`). A real bench, a point a second or
slower, stays at the fastest pace.
"""

from __future__ import annotations

import time
from collections.abc import Callable

__all__ = ["BUSY_HIGH", "BUSY_LOW", "FASTEST_MS", "SLOWEST_MS", "RedrawPace", "next_interval_ms"]

#: the shortest and the longest time between redraws (ms)
FASTEST_MS = 100
SLOWEST_MS = 1000
#: the share of wall time the window's thread spent on the CPU above which the pace slows,
#: and below which it quickens
BUSY_HIGH = 0.5
BUSY_LOW = 0.25


def next_interval_ms(interval_ms: int, busy: float) -> int:
    """The interval after one of ``interval_ms`` during which the window's thread was on the
    CPU a share ``busy`` (0..1) of the time."""
    if busy > BUSY_HIGH:
        return min(2 * interval_ms, SLOWEST_MS)
    if busy < BUSY_LOW:
        return max(interval_ms // 2, FASTEST_MS)
    return interval_ms


class RedrawPace:
    """Measures the calling thread's share of the CPU between calls of :meth:`tick` and gives
    the next interval (ms). Call it from the thread that draws. ``cpu_s`` and ``wall_s``: the
    thread's CPU clock and the wall clock (s; tests pass their own)."""

    def __init__(
        self,
        cpu_s: Callable[[], float] = time.thread_time,
        wall_s: Callable[[], float] = time.monotonic,
    ) -> None:
        self.interval_ms = FASTEST_MS
        self._cpu_s, self._wall_s = cpu_s, wall_s
        self._cpu = cpu_s()
        self._wall = wall_s()

    def tick(self) -> int:
        cpu, wall = self._cpu_s(), self._wall_s()
        busy = (cpu - self._cpu) / max(wall - self._wall, 1e-3)
        self._cpu, self._wall = cpu, wall
        self.interval_ms = next_interval_ms(self.interval_ms, busy)
        return self.interval_ms
