"""Engine events -> Qt: the one bridge from the engine's thread to the GUI thread.

The engine calls subscribers on its own thread. :class:`EngineEventAdapter` is such a
subscriber: it appends the event to a thread-safe queue and emits ``events_ready`` (a Qt
signal; the connection to a GUI-thread slot is queued because the emitter is another thread).
At most one emission is pending at a time, so a fast engine coalesces into batches instead of
flooding the event loop. The GUI slot calls :meth:`drain` and handles the batch.
"""

from __future__ import annotations

import queue
import threading
from typing import Any

from PySide6.QtCore import QObject, Signal

__all__ = ["EngineEventAdapter"]


class EngineEventAdapter(QObject):
    """Subscriber (``adapter(event)``) that turns engine events into one Qt signal per batch."""

    events_ready = Signal()

    def __init__(self, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._pending = threading.Event()
        self.n_received = 0

    def __call__(self, event: Any) -> None:
        """Called on the engine's thread: queue the event, signal the GUI if not yet pending."""
        self._queue.put(event)
        self.n_received += 1
        if not self._pending.is_set():
            self._pending.set()
            self.events_ready.emit()

    def drain(self) -> list[Any]:
        """Every queued event, oldest first (call on the GUI thread)."""
        self._pending.clear()
        out: list[Any] = []
        while True:
            try:
                out.append(self._queue.get_nowait())
            except queue.Empty:
                return out
