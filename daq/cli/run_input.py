"""The inputs of the commands that read a run file (``biafc figures``, ``biafc compare``,
``biafc calibrate``): the run file, read whole, and the chain file the model starts from."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from daq.cli.biafc import CliError

__all__ = ["read_run_and_chain", "read_run_file"]


def read_run_file(path: Path) -> Any:
    """The whole run file (``RunData``); a missing or unreadable file, or one without a scan,
    is a :class:`CliError` (one line)."""
    from protocols.runfile import RunFileError, read_run

    if not path.exists():
        raise CliError(f"run file {path} does not exist")
    try:
        data = read_run(path)
    except RunFileError as exc:  # names the file and what is wrong with it
        raise CliError(str(exc)) from None
    except (OSError, KeyError) as exc:
        why = (str(exc).splitlines() or [type(exc).__name__])[0]
        raise CliError(f"{path}: cannot read as a run file ({why})") from None
    if not data.scans:
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
