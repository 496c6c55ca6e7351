"""The inputs of the commands that put the model beside a run (``biafc compare``, ``biafc
calibrate``): the run file, read whole, and the chain file the model starts from."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from daq.cli.biafc import CliError

__all__ = ["read_run_and_chain"]


def read_run_and_chain(path: Path, chain: Path | None) -> tuple[Any, Any]:
    """``(RunData, ChainSpec | None)``; a missing or unreadable run file, a file without a scan
    or a bad chain file is a :class:`CliError` (one line)."""
    from protocols.runfile import RunFileError, read_run
    from sim_backend.dem import ChainFileError, load_chain_spec

    if not path.exists():
        raise CliError(f"run file {path} does not exist")
    try:
        data = read_run(path)
    except (RunFileError, OSError, KeyError) as exc:
        raise CliError(f"{path}: cannot read as a run file ({exc})") from exc
    if not data.scans:
        raise CliError(f"{path}: the run file holds no scan")
    spec = None
    if chain is not None:
        try:
            spec = load_chain_spec(chain)
        except ChainFileError as exc:
            raise CliError(str(exc)) from None
    return data, spec
