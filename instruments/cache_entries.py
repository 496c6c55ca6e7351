"""Entries kept in one JSON file of the user cache folder (:mod:`instruments.user_cache`), read
and merged best effort: the one mechanism behind the stability verdicts
(:mod:`sim_backend.dem.verdict_store`) and the parsed units (:mod:`instruments.unit_memo`).

The file is one JSON object, key -> entry. A missing, unreadable or damaged file reads as no
entries. A merge reads the file again, adds the new entries (the file starts again empty past
``max_entries``) and replaces it whole from a temporary file of its own (``os.replace``, atomic),
so a reader never sees half a file, and of two processes merging at once one may lose the
other's new entries, which are computed again next time. A folder that cannot be written is no
error: a cache, not a record.
"""

from __future__ import annotations

import contextlib
import json
import os
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = ["merge_entries", "read_entries"]


def read_entries(file: Path) -> dict[str, Any]:
    """The entries of ``file`` (none when it is missing, unreadable or not a JSON object)."""
    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def merge_entries(file: Path, batch: Mapping[str, Any], max_entries: int) -> None:
    """Add ``batch`` to the entries of ``file`` and write it again (best effort)."""
    tmp = file.with_name(f"{file.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    try:
        data = read_entries(file)
        if len(data) + len(batch) > max_entries:
            data = {}
        data.update(batch)
        file.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text(json.dumps(data), encoding="utf-8")
        os.replace(tmp, file)
    except OSError:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
