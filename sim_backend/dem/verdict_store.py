"""The step-stability verdicts kept in the user's cache folder (``step-stability.json``).

One JSON object, key -> entry (:func:`sim_backend.dem.step_limit.range_key` -> ``[start_m,
stable_to_m, unstable_at_m]``, ``"inf"`` for none). Best effort: a cache folder that cannot be
read or written is no error, only a verdict computed again.

:func:`store` keeps a new verdict in memory and the file is written once, when the process ends
(``atexit``), or when :data:`MAX_PENDING` verdicts wait: reading, merging and replacing the file
costs 0.2-0.4 ms, a tenth of a first check, and a background thread for it contended for the GIL
with the check itself. :func:`load` sees this process's pending verdicts as well as the file's. A
process killed before it ends loses its new verdicts, which the next process computes again (a
cache, not a record). The file is read and merged by :mod:`instruments.cache_entries` (whole
files only; of two processes writing at once, one's new entries can be lost and are computed
again next time).
"""

from __future__ import annotations

import atexit
import threading
from pathlib import Path
from typing import Any

from instruments.cache_entries import merge_entries, read_entries

__all__ = ["flush", "load", "path", "store"]

#: the file starts again empty past this many entries (a verdict is recomputed in milliseconds)
MAX_ENTRIES = 4096
#: pending verdicts written at once when this many wait
MAX_PENDING = 64

_LOCK = threading.Lock()
_PENDING: dict[Path, dict[str, list[Any]]] = {}  # cache file -> key -> entry


def path() -> Path:
    """The cache file in the user's cache folder (:func:`instruments.user_cache.cache_dir`)."""
    from instruments.user_cache import cache_dir

    return cache_dir() / "step-stability.json"


def load(key: str) -> list[Any] | None:
    """The entry stored under ``key`` (this process's pending one first, else the file's), or
    None (none, or the file unreadable)."""
    file = path()
    with _LOCK:
        entry = _PENDING.get(file, {}).get(key)
    if entry is None:
        entry = read_entries(file).get(key)
    return entry if isinstance(entry, list) else None


def store(key: str, entry: list[Any]) -> None:
    """Keep ``entry`` under ``key``: in memory now, in the cache file at :func:`flush` (at the
    latest when the process ends)."""
    file = path()  # the cache folder of now (a test may change it later)
    with _LOCK:
        pending = _PENDING.setdefault(file, {})
        pending[key] = entry
        full = len(pending) >= MAX_PENDING
    if full:
        flush()


def flush() -> None:
    """Write every verdict stored so far by this process into the file."""
    with _LOCK:  # held while writing: two flushes do not write the same file in turn
        batches = dict(_PENDING)
        _PENDING.clear()
        for file, batch in batches.items():
            merge_entries(file, batch, MAX_ENTRIES)


atexit.register(flush)
