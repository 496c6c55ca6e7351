"""A watcher beside a block of work: a daemon thread that runs ``watch(stop)`` while the block
runs, and is stopped (``stop`` set) and joined when it ends. In the lowest layer so that every
layer's notices share it (the compile notice, a study's no-worker notice)."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

__all__ = ["beside"]


@contextmanager
def beside(
    watch: Callable[[threading.Event], None], name: str, join_s: float | None = None
) -> Iterator[None]:
    """Run ``watch(stop)`` on a daemon thread named ``name`` during the block; at its end set
    ``stop`` and wait for the thread (at most ``join_s`` s; ``None``: until it returns)."""
    stop = threading.Event()
    thread = threading.Thread(target=watch, args=(stop,), name=name, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(join_s)
