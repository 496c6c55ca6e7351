"""The run store: a run file with provenance, opened new or resumed, on top of
:mod:`protocols.runfile` (which alone knows the layout).

* :func:`check_output_path` refuses an existing file (unless resuming) or an unwritable folder,
  before any instrument moves.
* :func:`create_run` writes the provenance: protocol and bench text, every instrument's
  snapshot, software version, host, start time, seed, status ``running``.
* :func:`resume_run` verifies that the protocol in the file is the one given (same parsed
  content) and that the scan axes match, then re-opens it to append points and log rows.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import h5py
import numpy as np

from daq.store.recover import clear_consistency_flags
from protocols.runfile import ChainInfo, RunFileWriter, ScanSpec, read_run
from protocols.schema import ProtocolFile, parse_protocol
from protocols.yamlfile import ConfigError

__all__ = ["StoreError", "check_output_path", "create_run", "resume_run", "stored_seed"]


class StoreError(ValueError):
    """The output or resume file cannot be used; the message is one line."""


def check_output_path(path: Path, *, resume: bool = False) -> None:
    """Refuse a path that cannot take a new run (or, resuming, a missing file)."""
    if resume:
        if not path.is_file():
            raise StoreError(f"--resume: {path} does not exist")
        if not os.access(path, os.W_OK):
            raise StoreError(f"--resume: {path} is not writable")
        return
    if path.exists():
        raise StoreError(f"--out: {path} exists already (use --resume {path} to continue it)")
    parent = path.parent if str(path.parent) else Path(".")
    probe = parent
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir() or not os.access(probe, os.W_OK | os.X_OK):
        raise StoreError(f"--out: cannot write in {probe} (permission denied)")


def create_run(
    path: Path,
    *,
    backend: Literal["sim", "hardware"],
    chain: ChainInfo,
    scans: Sequence[ScanSpec],
    protocol_yaml: str,
    bench_yaml: str,
    snapshot: Mapping[str, Any],
    seed: int | None,
) -> RunFileWriter:
    """A new run file with its provenance (status ``running``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    extra: dict[str, Any] = {}
    if seed is not None:
        extra["seed"] = int(seed)
    return RunFileWriter.create(
        path,
        backend=backend,
        chain=chain,
        scans=scans,
        protocol_yaml=protocol_yaml,
        bench_yaml=bench_yaml,
        snapshot=snapshot,
        extra_attrs=extra,
    )


def stored_seed(path: Path) -> int | None:
    """The seed a run file was started with (``None`` when not recorded)."""
    with h5py.File(path, "r", swmr=True) as f:
        v = f.attrs.get("seed")
    return None if v is None else int(v)


def resume_run(path: Path, pf: ProtocolFile, scans: Sequence[ScanSpec]) -> RunFileWriter:
    """Re-open ``path`` to continue it with protocol ``pf``; refused when they differ."""
    try:
        run = read_run(path)
    except (OSError, ValueError) as exc:
        raise StoreError(f"--resume: {exc}") from None
    if run.status == "complete":
        raise StoreError(f"--resume: {path} is complete already")
    try:
        stored = parse_protocol(str(run.attrs.get("protocol_yaml", "")), f"{path}:protocol_yaml")
    except ConfigError as exc:
        raise StoreError(f"--resume: the protocol stored in {path} is unreadable ({exc})") from None
    if stored.protocol.model_dump() != pf.protocol.model_dump():
        raise StoreError(
            f"--resume: {path} was started with another protocol ({stored.protocol.name!r}); "
            "give the same protocol file"
        )
    for spec in scans:
        got = run.scans.get(spec.direction)
        if (
            got is None
            or not np.array_equal(got.amplitudes, spec.amplitudes)
            or not np.array_equal(got.cylinders, spec.cylinders)
            or got.time_s.shape != spec.time_s.shape
        ):
            raise StoreError(
                f"--resume: the {spec.direction} scan in {path} does not match this protocol "
                "on this bench"
            )
    clear_consistency_flags(path)  # a writer killed under SWMR leaves them set
    try:
        return RunFileWriter.open_existing(path)
    except OSError as exc:
        raise StoreError(f"--resume: cannot open {path} for writing ({exc})") from None
