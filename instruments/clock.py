"""Clocks for polling loops: the wall clock, or a simulated one injected by the simulated bench."""

from __future__ import annotations

import time
from typing import Protocol, runtime_checkable

__all__ = ["Clock", "SystemClock"]


@runtime_checkable
class Clock(Protocol):
    """``now()`` in s (monotonic) and ``sleep(dt_s)``."""

    def now(self) -> float: ...

    def sleep(self, dt_s: float) -> None: ...


class SystemClock:
    """The real monotonic clock."""

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, dt_s: float) -> None:
        if dt_s > 0:
            time.sleep(dt_s)
