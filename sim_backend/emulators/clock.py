"""Simulated time shared by the emulators and the drivers' polling loops."""

from __future__ import annotations

import time

__all__ = ["SimClock"]


class SimClock:
    """Simulated seconds; ``sleep(dt)`` advances them (and waits ``dt / speedup`` wall seconds
    when ``speedup > 0``; ``speedup = 0`` never sleeps)."""

    def __init__(self, speedup: float = 0.0, start_s: float = 0.0) -> None:
        if not speedup >= 0:
            raise ValueError(f"clock speed-up must be >= 0, got {speedup!r}")
        self.speedup = float(speedup)
        self._now = float(start_s)

    def now(self) -> float:
        return self._now

    def sleep(self, dt_s: float) -> None:
        if dt_s <= 0:
            return
        self._now += dt_s
        if self.speedup > 0:
            time.sleep(dt_s / self.speedup)

    def advance(self, dt_s: float) -> None:
        """Advance without wall waiting."""
        if dt_s > 0:
            self._now += dt_s
