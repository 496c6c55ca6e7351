"""The one check every writing command makes before its work: can it write where it was told
(:func:`daq.store.writable.cannot_write`)? A refusal is a :class:`~daq.cli.biafc.CliError`:
one line, exit 2."""

from __future__ import annotations

from pathlib import Path

from daq.cli.biafc import CliError
from daq.store.writable import cannot_write

__all__ = ["can_write", "can_write_folder"]


def can_write(target: Path, flag: str) -> None:
    """Refuse (one line) when the file ``target``, named by option ``flag``, cannot be
    written: a folder of that name included (it passed, and the command failed after its
    work: ``bands --csv``, ``calibrate --out``, ``accuracy --plot``)."""
    target = Path(target)
    if target.is_dir():
        raise CliError(f"{flag}: {target} is a folder; give a file name")
    problem = cannot_write(target, flag)
    if problem is not None:
        raise CliError(problem)


def can_write_folder(target: Path, flag: str) -> None:
    """As :func:`can_write`, for a folder the command writes its files into: an existing file
    of that name is refused too (it ended in a ``FileExistsError`` traceback, after the work)."""
    target = Path(target)
    if target.exists() and not target.is_dir():
        raise CliError(f"{flag}: {target} is a file; give a folder to write into")
    problem = cannot_write(target, flag)
    if problem is not None:
        raise CliError(problem)
