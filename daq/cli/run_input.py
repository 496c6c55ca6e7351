"""The inputs of the commands that read a run file (``biafc figures``, ``biafc compare``,
``biafc calibrate``): the run file, read whole, and the chain file the model starts from."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from daq.cli.biafc import CliError

__all__ = ["read_run_and_chain", "read_run_file", "read_run_or_study"]


def read_run_file(path: Path) -> Any:
    """The whole run file (``RunData``); a missing or unreadable file, or one without a scan,
    is a :class:`CliError` (one line)."""
    from protocols.runfile import read_run

    return _run_or_refuse(path, read_run)


def read_run_or_study(path: Path) -> Any:
    """The whole file, ``StudyData`` for a study output, else ``RunData``, read through one open
    (a damaged file waits its grace once, :mod:`protocols.outputfile`). Refused as
    :func:`read_run_file` (:class:`CliError`), except a study output that does not read:
    :class:`~protocols.studyfile.StudyFileError`, for the caller to name."""
    from protocols.outputfile import read_output

    return _run_or_refuse(path, read_output)


def _run_or_refuse(path: Path, read: Callable[[Path], Any]) -> Any:
    from protocols.runfile import RunData, RunFileError

    if not path.exists():
        raise CliError(f"run file {path} does not exist")
    try:
        data = read(path)
    except RunFileError as exc:  # names the file and what is wrong with it
        raise CliError(str(exc)) from None
    except (OSError, KeyError) as exc:
        why = (str(exc).splitlines() or [type(exc).__name__])[0]
        raise CliError(f"{path}: cannot read as a run file ({why})") from None
    if isinstance(data, RunData) and not data.scans:
        raise CliError(f"{path}: the run file holds no scan")
    return data


def read_run_and_chain(path: Path, chain: Path | None) -> tuple[Any, Any]:
    """``(RunData, ChainSpec | None)`` as :func:`read_run_file`; a bad chain file is a
    :class:`CliError` too."""
    from sim_backend.dem import ChainFileError, load_chain_spec

    data = read_run_file(path)
    spec = None
    if chain is not None:
        try:
            spec = load_chain_spec(chain)
        except ChainFileError as exc:
            raise CliError(str(exc)) from None
    return data, spec
