"""The far end of a serial line in the tests: a thread that answers each line read from a pseudo
terminal's master side (``answer(line)`` -> the bytes to send back, or ``None``)."""

from __future__ import annotations

import os
import select
import threading
from collections.abc import Callable


def serve_lines(fd: int, answer: Callable[[bytes], bytes | None], stop: threading.Event) -> None:
    """Until ``stop``: read lines (``\\n``-ended, a trailing ``\\r`` dropped) from ``fd`` and write
    ``answer(line)`` back."""
    buf = b""
    while not stop.is_set():
        ready, _, _ = select.select([fd], [], [], 0.02)
        if not ready:
            continue
        buf += os.read(fd, 4096)
        while b"\n" in buf:
            line, buf = buf.split(b"\n", 1)
            reply = answer(line.rstrip(b"\r"))
            if reply is not None:
                os.write(fd, reply)
