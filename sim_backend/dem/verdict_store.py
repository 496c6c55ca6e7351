"""The step-stability verdicts kept in the user's cache folder (``step-stability.json``).

One JSON object, key -> entry (:func:`sim_backend.dem.step_limit.range_key` -> ``[start_m,
stable_to_m, unstable_at_m]``, ``"inf"`` for none). Best effort: a cache folder that cannot be
read or written is no error, only a verdict computed again.

:func:`store` hands the write to a background thread (a non-daemon one: the interpreter waits for
it at exit, so a stored verdict is not lost), so the check that computed a verdict does not wait
for the file: reading, merging and replacing it costs 0.3-0.4 ms, a tenth of a first check. Two
processes may store at once: each writes its own temporary file and replaces the cache file with
it (``os.replace``, atomic), so the file is always whole; one of two simultaneous new entries can
be lost, and is computed again next time.
"""

from __future__ import annotations

import json
import os
import threading
from pathlib import Path
from typing import Any

__all__ = ["flush", "load", "path", "store"]

#: the file starts again empty past this many entries (a verdict is recomputed in milliseconds)
MAX_ENTRIES = 4096

_LOCK = threading.Lock()
_PENDING: dict[str, list[Any]] = {}
_WRITER: threading.Thread | None = None
_WRITING = False  # a writer runs and will take what is pending (under _LOCK)


def path() -> Path:
    """The cache file in the user's cache folder (:func:`sim_backend.dem.user_cache.cache_dir`)."""
    from sim_backend.dem.user_cache import cache_dir

    return cache_dir() / "step-stability.json"


def _read(file: Path) -> dict[str, Any]:
    try:
        data = json.loads(file.read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def load(key: str) -> list[Any] | None:
    """The entry stored under ``key``, or None (none, or the file unreadable). Waits for this
    process's pending writes first."""
    flush()
    entry = _read(path()).get(key)
    return entry if isinstance(entry, list) else None


def _merge(batch: dict[str, list[Any]]) -> None:
    file = path()
    try:
        data = _read(file)
        if len(data) + len(batch) > MAX_ENTRIES:
            data = {}
        data.update(batch)
        file.parent.mkdir(parents=True, exist_ok=True)
        tmp = file.with_suffix(f".{os.getpid()}.{threading.get_ident()}.tmp")
        tmp.write_text(json.dumps(data))
        os.replace(tmp, file)
    except OSError:
        pass


def _write_pending() -> None:
    global _WRITING
    while True:
        with _LOCK:
            if not _PENDING:
                _WRITING = False
                return
            batch = dict(_PENDING)
            _PENDING.clear()
        _merge(batch)


def store(key: str, entry: list[Any]) -> None:
    """Merge ``entry`` under ``key`` into the cache file, in a background thread."""
    global _WRITER, _WRITING
    with _LOCK:
        _PENDING[key] = entry
        if _WRITING:
            return  # the running writer takes it
        _WRITING = True
        _WRITER = threading.Thread(target=_write_pending, name="biafc-verdict-store")
        _WRITER.start()


def flush() -> None:
    """Wait until every verdict stored so far by this process is in the file."""
    with _LOCK:
        writer = _WRITER
    if writer is not None and writer is not threading.current_thread():
        writer.join()
