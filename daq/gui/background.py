"""Run a blocking call (connect, instrument snapshot, safe state, reading a run file) off the
GUI thread and get its result back on the GUI thread through a Qt signal."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any, ClassVar

from PySide6.QtCore import QObject, Signal

__all__ = ["BackgroundCall"]


class BackgroundCall(QObject):
    """``BackgroundCall(fn, on_done)``: calls ``fn()`` on a worker thread, then
    ``on_done(result, error)`` on the GUI thread (``error`` is the exception or ``None``).

    The object keeps itself alive until done. ``worker`` is the thread (join it in tests).
    """

    #: no arguments: the result stays on the Python side (passing Python objects, None
    #: included, through queued signals is what PySide6 gets wrong at shutdown)
    done = Signal()
    _alive: ClassVar[set[BackgroundCall]] = set()

    def __init__(
        self,
        fn: Callable[[], Any],
        on_done: Callable[[Any, BaseException | None], None],
        name: str = "biafc-gui-worker",
    ) -> None:
        super().__init__()
        self._fn = fn
        self._on_done = on_done
        self._result: Any = None
        self._error: BaseException | None = None
        self.done.connect(self._finish)
        BackgroundCall._alive.add(self)
        self.worker = threading.Thread(target=self._work, name=name, daemon=True)
        self.worker.start()

    def _work(self) -> None:
        try:
            self._result = self._fn()
        except Exception as exc:
            self._error = exc
        self.done.emit()

    def _finish(self) -> None:
        result, error = self._result, self._error
        self._result = self._error = None
        # the worker holds this object (its thread's target) until it ends: let it end first,
        # so that the last reference, and any QObject it keeps alive, goes on the GUI thread (a
        # QObject freed on the worker deadlocks with the GUI thread deleting widgets)
        if threading.current_thread() is not self.worker:
            self.worker.join()
        BackgroundCall._alive.discard(self)
        self._on_done(result, error)
