"""Whether a command can write where it was told to, asked before it does any work.

``run_protocol`` checked its ``--out`` folder up front; the other commands that write found out
at their end: ``biafc simulate`` ran its model for 20 s, then failed to create the file;
``biafc figures`` beside a run file in a read-only folder ended in a ``PermissionError``
traceback. :func:`cannot_write` answers for any file or folder a command will make.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

__all__ = ["cannot_create_in", "cannot_write", "nearest_existing"]


def nearest_existing(path: Path) -> Path:
    """``path`` itself, or its nearest ancestor that exists (``.`` for a bare relative name)."""
    for folder in (path, *path.parents):
        if folder.exists():
            return folder
    return Path(".")  # a relative path whose every ancestor is missing: the working folder


def cannot_create_in(folder: Path) -> str | None:
    """Why no file can be created in ``folder`` (tried with a temporary file, removed at once:
    ``os.access`` says yes to root everywhere, also in ``/proc``), or ``None``."""
    try:
        fd, name = tempfile.mkstemp(prefix=".biafc-probe-", dir=folder)
    except OSError as exc:
        return exc.strerror or str(exc)
    os.close(fd)
    try:
        os.unlink(name)
    except OSError:
        pass
    return None


def cannot_write(target: Path, flag: str) -> str | None:
    """Why the file or folder ``target`` (``flag``: the option that named it, e.g. ``--out``)
    cannot be made: its nearest existing folder is a file, or cannot be written (one line), or
    ``None``."""
    probe = nearest_existing(target if target.is_dir() else target.parent)
    if not probe.is_dir():
        return f"{flag}: cannot write {target}: {probe} is a file, not a folder"
    if not os.access(probe, os.W_OK | os.X_OK):
        return f"{flag}: cannot write in {probe} (permission denied)"
    cannot = cannot_create_in(probe)
    if cannot is not None:
        return f"{flag}: cannot write {target}: nothing can be created in {probe} ({cannot})"
    return None
