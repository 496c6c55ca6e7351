"""The line a command prints as each figure's files are saved (``written NAME: a.png, a.pdf``),
at once: ``biafc figures``, ``biafc compare`` and ``biafc calibrate --figures`` hand it to the
writers that draw figure after figure, so each line appears as its files do."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

__all__ = ["print_written"]


def print_written(name: str, paths: Sequence[Path]) -> None:
    """``written NAME: path, path`` on stdout, flushed."""
    print(f"written {name}: {', '.join(str(p) for p in paths)}", flush=True)
