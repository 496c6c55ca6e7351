"""Events of the run engine, delivered to subscribers as plain callbacks.

A subscriber is ``Callable[[RunEvent], None]``; it is called on the engine's thread, so a GUI
adapts it to a Qt signal (queued connection) and never touches instruments itself. A subscriber
that raises is logged and dropped; it never stops a run.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

__all__ = ["EventBus", "EventKind", "RunEvent", "RunState", "Subscriber"]


class RunState(StrEnum):
    """States of the run engine: idle -> running <-> paused -> complete | aborted | failed,
    and unsafe (the safe state could not be confirmed) or refused (nothing moved)."""

    IDLE = "idle"
    RUNNING = "running"
    PAUSED = "paused"
    COMPLETE = "complete"
    ABORTED = "aborted"
    FAILED = "failed"
    UNSAFE = "unsafe"
    REFUSED = "refused"

    @property
    def finished(self) -> bool:
        return self in (
            RunState.COMPLETE,
            RunState.ABORTED,
            RunState.FAILED,
            RunState.UNSAFE,
            RunState.REFUSED,
        )


class EventKind(StrEnum):
    """What happened. ``data`` keys per kind are listed in :class:`RunEvent`."""

    STATE_CHANGED = "state_changed"
    RUN_STARTED = "run_started"
    POINT_STARTED = "point_started"
    POINT_DONE = "point_done"
    POINT_FAILED = "point_failed"
    PROGRESS = "progress"
    WARNING = "warning"
    #: what the bench is doing between points (``text``: "homing the stage")
    STATUS = "status"
    FINISHED = "finished"


@dataclass(frozen=True)
class RunEvent:
    """One event.

    ``data`` by kind:

    * ``state_changed``: ``state`` (RunState value), ``previous``
    * ``run_started``: ``path``, ``n_points``, ``n_todo``, ``n_already``, ``estimated_s`` (from
      the bench that runs it, :mod:`daq.engine.eta`), ``estimate_basis`` (what it rests on)
    * ``point_started`` / ``point_done`` / ``point_failed``: ``direction``, ``amplitude_index``,
      ``cylinder_index``, ``amplitude`` (SI), ``amplitude_units``, ``cylinder`` (1-based),
      ``attempt``; ``point_done`` adds ``velocity_m_per_s``, ``drive`` (V), ``time_s`` (each
      ``[S]``);
      ``point_failed`` adds ``reason``
    * ``progress``: ``done``, ``total``, ``elapsed_s``, ``eta_s`` (the bench's estimate refined
      by the measured point times), ``direction``, ``amplitude``,
      ``cylinder``
    * ``warning``: ``message``
    * ``status``: ``text`` (what the bench does between points, e.g. homing the stage)
    * ``finished``: ``status``, ``reason``, ``path``, ``n_done``, ``n_failed``, ``n_points``,
      ``n_measured_now``, ``n_already``, ``unconfirmed`` (list of outputs to switch off by
      hand), ``safe_state_s``, ``points_failed_only`` (as :class:`daq.engine.RunResult`)
    """

    kind: EventKind
    message: str = ""
    data: dict[str, Any] = field(default_factory=dict)
    time: float = field(default_factory=time.time)


Subscriber = Callable[[RunEvent], None]


class EventBus:
    """Thread-safe list of subscribers."""

    def __init__(self) -> None:
        self._subs: list[Subscriber] = []
        self._lock = threading.Lock()
        self.errors: list[str] = []

    def subscribe(self, callback: Subscriber) -> Callable[[], None]:
        """Add ``callback``; returns a function that removes it."""
        with self._lock:
            self._subs.append(callback)

        def unsubscribe() -> None:
            with self._lock:
                if callback in self._subs:
                    self._subs.remove(callback)

        return unsubscribe

    def emit(self, event: RunEvent) -> None:
        with self._lock:
            subs = list(self._subs)
        for cb in subs:
            try:
                cb(event)
            except Exception as exc:  # a broken subscriber never stops a run
                self.errors.append(f"subscriber {cb!r} raised {exc!r}; dropped")
                with self._lock:
                    if cb in self._subs:
                        self._subs.remove(cb)
