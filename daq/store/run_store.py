"""The run store: a run file with provenance, opened new or resumed, on top of
:mod:`protocols.runfile` (which alone knows the layout).

* :func:`check_output_path` refuses an existing file (unless resuming) or an unwritable folder,
  before any instrument moves.
* :func:`create_run` writes the provenance: protocol and bench text, every instrument's
  snapshot, software version, host, start time, seed, status ``running``.
* :func:`resume_run` verifies that the protocol in the file is the one given (same parsed
  content), that the bench is the one it was started on (:mod:`daq.store.resume_check`; an
  explicit override is recorded in the file) and that the scan axes match, then re-opens it to
  append points and log rows. The caller holds the file's lock (:mod:`daq.store.lock`).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np

from daq.store.recover import clear_consistency_flags
from daq.store.resume_check import bench_differences, chain_differences, model_differences
from daq.store.writable import cannot_write
from protocols.bench import BenchFile
from protocols.legacy import upgrade_protocol_text
from protocols.one_line import first_line
from protocols.runfile import ChainInfo, RunFileWriter, ScanSpec
from protocols.schema import ProtocolFile, names_a_run_file, parse_protocol
from protocols.yamlfile import ConfigError

__all__ = [
    "StoreError",
    "check_output_path",
    "check_resume",
    "create_run",
    "free_name",
    "resume_run",
    "stored_request",
    "stored_seed",
]


class StoreError(ValueError):
    """The output or resume file cannot be used; the message is one line."""


def free_name(path: Path) -> Path:
    """The first ``NAME_2.h5``, ``NAME_3.h5``... beside ``path`` that does not exist."""
    for k in range(2, 10_000):
        cand = path.with_name(f"{path.stem}_{k}{path.suffix or '.h5'}")
        if not cand.exists():
            return cand
    return path.with_name(f"{path.stem}_new{path.suffix or '.h5'}")


def _run_status(path: Path, *, resuming: bool = False) -> str | None:
    """The ``status`` of a biafc run file, or ``None`` when ``path`` is not one. ``resuming``:
    a file that does not open (truncated, damaged, no HDF5 file) is refused here
    (:class:`StoreError`, the line ``--resume`` refuses it with later), so the wait before
    that refusal (up to 0.5 s, :mod:`protocols.outputfile`) is paid once."""
    from protocols.runfile import FORMAT, RunFileError, one_line_errors, open_for_reading

    try:
        with one_line_errors(path), open_for_reading(path) as f:  # h5py's errors: one line
            if f.attrs.get("format") != FORMAT:
                return None
            status = f.attrs.get("status", "")
    except RunFileError as exc:
        if resuming:
            raise StoreError(f"--resume: {str(exc).splitlines()[0]}") from None
        return None
    return status.decode() if isinstance(status, bytes) else str(status)


def _complete(path: Path) -> str:
    return (
        f"--resume: {path} is complete already, nothing to continue; to measure again "
        f"write a new file (--out {free_name(path)})"
    )


def check_output_path(path: Path, *, resume: bool = False) -> None:
    """Refuse a path that cannot take a new run (or, resuming, a missing, unreadable or
    complete file); each message says what to do instead."""
    if resume:
        if path.is_dir():
            raise StoreError(f"--resume: {path} is a folder; give the run file to continue")
        if not path.is_file():
            raise StoreError(f"--resume: {path} does not exist")
        if not os.access(path, os.W_OK):
            raise StoreError(f"--resume: {path} is not writable")
        if _run_status(path, resuming=True) == "complete":
            raise StoreError(_complete(path))
        return
    if path.is_dir():
        raise StoreError(f"--out: {path} is a folder; give a run file name (e.g. {path}/run.h5)")
    if not names_a_run_file(path):
        raise StoreError(
            f"--out: {path}: a run file's name ends in .h5 (its log is written beside it as "
            f"NAME.log); e.g. --out {path.with_name(path.name + '.h5')}"
        )
    if path.exists():
        status = _run_status(path)
        if status is None:
            why = "exists already and is not a run file"
        elif status == "complete":
            why = "is a complete run already"
        else:
            from daq.store.lock import in_use_by

            busy = in_use_by(path)  # a run writing it now: not one "left" to continue
            if busy is not None:
                raise StoreError(f"--out: {busy}; or write a new file (--out {free_name(path)})")
            raise StoreError(
                f"--out: {path} exists already (a run left {status}): continue it with "
                f"--resume {path}, or write a new file (--out {free_name(path)})"
            )
        raise StoreError(f"--out: {path} {why}; write a new file (--out {free_name(path)})")
    problem = cannot_write(path, "--out")
    if problem is not None:
        raise StoreError(problem)


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
    from daq.store.provenance import provenance_attrs

    path.parent.mkdir(parents=True, exist_ok=True)
    extra: dict[str, Any] = provenance_attrs()
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
    from protocols.runfile import open_for_reading

    with open_for_reading(path) as f:
        v = f.attrs.get("seed")
    return None if v is None else int(v)


def parse_stored_protocol(protocol_yaml: str, path: Path) -> ProtocolFile:
    """The protocol text stored in run file ``path``, validated; a run started before
    amplitudes had to say Vpp or Vpk stored a bare ``2 V``, which then meant Vpp and is read so
    (:mod:`protocols.legacy`). :class:`ConfigError` when it cannot be read."""
    return parse_protocol(upgrade_protocol_text(protocol_yaml), f"{path}:protocol_yaml")


def stored_request(path: Path) -> tuple[ProtocolFile, BenchFile]:
    """The protocol and the bench a run file was started with (``--resume RUN.h5`` alone),
    parsed from the texts stored in it; :class:`StoreError` (one line) when they cannot be."""
    from protocols.bench import parse_bench
    from protocols.runfile import RunFileError, stored_texts

    try:
        protocol_yaml, bench_yaml = stored_texts(path)
    except (OSError, RunFileError) as exc:
        raise StoreError(f"--resume: {exc}") from None
    if not protocol_yaml.strip():
        raise StoreError(f"--resume: {path} holds no protocol; give the protocol file too")
    try:
        pf = parse_stored_protocol(protocol_yaml, path)
        bf = parse_bench(bench_yaml, f"{path}:bench_yaml")
    except ConfigError as exc:
        raise StoreError(f"--resume: the request stored in {path} is unreadable ({exc})") from None
    return pf, bf


def _protocol_differences(stored: ProtocolFile, given: ProtocolFile) -> list[str]:
    """``"averages: 2 in the file, 3 now"`` for each top-level field that differs."""
    a, b = stored.protocol.model_dump(), given.protocol.model_dump()
    return [
        f"{k}: {a.get(k)!r} in the file, {b.get(k)!r} now"
        for k in sorted(set(a) | set(b))
        if a.get(k) != b.get(k)
    ]


def _stored_chain_spec(model: dict[str, Any] | None) -> dict[str, Any] | None:
    """The simulated bench's chain as a run recorded it (``chain_spec`` of its
    :func:`_stored_model`), or None."""
    spec = model.get("chain_spec") if model is not None else None
    return spec if isinstance(spec, dict) else None


_MODEL = "simulated bench model: "


def _stored_model(snapshot_json: Any) -> dict[str, Any] | None:
    """The simulated bench's model as a run recorded it (``/snapshot``'s
    ``simulation_model``), or None (a lab bench's run)."""
    try:
        text = snapshot_json.decode() if isinstance(snapshot_json, bytes) else str(snapshot_json)
        model = json.loads(text).get("simulation_model")
    except (ValueError, AttributeError):
        return None
    return model if isinstance(model, dict) else None


def check_resume(
    path: Path,
    pf: ProtocolFile,
    bench: BenchFile | None,
    axes: Mapping[str, tuple[Any, Any]],
    *,
    accept_bench_change: bool = False,
    n_samples: int | None = None,
) -> list[str]:
    """Whether ``path`` may be continued with protocol ``pf`` on ``bench``; reads only the
    file's attributes and scan axes (never its records), so it runs before any instrument is
    connected (``daq.request``) and again as the writer opens the file (:func:`resume_run`).

    ``axes``: direction -> (amplitudes ``[A]``, cylinders ``[C]``) this request measures;
    ``n_samples``: the record length it expects (``None``: not compared). Returns the bench
    differences accepted with ``accept_bench_change`` (empty when the benches match); raises
    :class:`StoreError` (one line) for a file that is no run file, complete, started with
    another protocol or a modified one, on another bench, or with other scan axes."""
    from protocols.runfile import DIRECTIONS, RunFileError, open_for_reading, stored_texts

    try:
        protocol_yaml, bench_yaml = stored_texts(path)  # refuses a file that is no run file
        with open_for_reading(path) as f:
            status = f.attrs.get("status", "")
            scans: dict[str, tuple[Any, Any, int]] = {}
            for d in DIRECTIONS if "scan" in f else ():
                if d not in f["scan"]:
                    continue
                g = f["scan"][d]
                scans[d] = (g["amplitudes"][...], g["cylinders"][...], g["time"].shape[0])
            snapshot_json = f["snapshot"].attrs.get("json", "{}") if "snapshot" in f else "{}"
    except RunFileError as exc:  # names the file
        raise StoreError(f"--resume: {str(exc).splitlines()[0]}") from None
    except (OSError, KeyError, ValueError, TypeError) as exc:  # h5py's, inside the file
        why = first_line(exc)
        raise StoreError(f"--resume: {path}: damaged HDF5 file, cannot be read ({why})") from None
    text = {"protocol_yaml": protocol_yaml, "bench_yaml": bench_yaml}
    if (status.decode() if isinstance(status, bytes) else str(status)) == "complete":
        raise StoreError(_complete(path))
    try:
        stored = parse_stored_protocol(text["protocol_yaml"], path)
    except ConfigError as exc:
        raise StoreError(f"--resume: the protocol stored in {path} is unreadable ({exc})") from None
    if stored.protocol.model_dump() != pf.protocol.model_dump():
        same_name = stored.protocol.name == pf.protocol.name
        what = (
            f"protocol {pf.protocol.name!r} as it was then ("
            + "; ".join(_protocol_differences(stored, pf)[:3])
            + ")"
            if same_name
            else f"{stored.protocol.name!r}, not {pf.protocol.name!r}"
        )
        raise StoreError(
            f"--resume: {path} was started with another protocol ({what}); "
            "give the same protocol file"
        )
    diffs: list[str] = []
    if bench is not None:
        diffs = bench_differences(text["bench_yaml"], bench, str(path))
        model = _stored_model(snapshot_json)  # the snapshot's JSON, parsed once
        diffs += chain_differences(_stored_chain_spec(model), bench, str(path))
        diffs += model_differences(model, bench, str(path))
        if diffs and not accept_bench_change and all(d.startswith(_MODEL) for d in diffs):
            raise StoreError(  # the same bench: only this software's model changed
                f"--resume: {path} was measured with another simulated-bench model "
                f"({'; '.join(diffs)}); give --accept-bench-change to continue it with this "
                "one, recording the change in the file"
            )
        if diffs and not accept_bench_change:
            raise StoreError(
                f"--resume: {path} was started on another bench ({len(diffs)} difference(s): "
                + "; ".join(diffs)
                + "); resume on the same bench, or give --accept-bench-change to record "
                "the change in the file"
            )
    for direction, (amplitudes, cylinders) in axes.items():
        got = scans.get(direction)
        if (
            got is None
            or not np.array_equal(got[0], amplitudes)
            or not np.array_equal(got[1], cylinders)
            or (n_samples is not None and got[2] != n_samples)
        ):
            raise StoreError(
                f"--resume: the {direction} scan in {path} does not match this protocol "
                "on this bench"
            )
    return diffs


def resume_run(
    path: Path,
    pf: ProtocolFile,
    scans: Sequence[ScanSpec],
    *,
    bench: BenchFile | None = None,
    accept_bench_change: bool = False,
    seed: int | None = None,
) -> RunFileWriter:
    """Re-open ``path`` to continue it with protocol ``pf`` on ``bench``; refused
    (:class:`StoreError`) when the protocol, the bench or the scan axes differ. With
    ``accept_bench_change`` a different bench is accepted and recorded in the file (root
    attribute ``bench_overrides_json``: a list of {time, differences, bench_yaml}). Each
    resume appends an entry to ``resumes_json``: its start time (``started``, the form of the
    root's time stamps), its provenance, ``seed`` (the simulated bench's seed of this resume;
    the root's ``seed`` stays the start's) and ``bench_yaml``, the bench text it ran with,
    whenever that differs from the root's ``bench_yaml`` at all (also where the comparison
    ignores the difference: names, addresses, the simulated bench's faults)."""
    diffs = check_resume(
        path,
        pf,
        bench,
        {s.direction: (s.amplitudes, s.cylinders) for s in scans},
        accept_bench_change=accept_bench_change,
        n_samples=scans[0].time_s.shape[0] if scans else None,
    )
    from daq.store.provenance import provenance_attrs
    from protocols.runfile import now_iso, open_for_reading

    keys = ("resumes_json", "bench_overrides_json", "bench_yaml")
    try:
        with open_for_reading(path) as f:
            prior = {k: f.attrs.get(k, "[]" if k.endswith("_json") else "") for k in keys}
    except OSError as exc:
        raise StoreError(f"--resume: {exc}") from None
    prior = {k: v.decode() if isinstance(v, bytes) else str(v) for k, v in prior.items()}
    extra: dict[str, Any] = {}
    started = now_iso()
    resumes = json.loads(prior["resumes_json"] or "[]")
    entry: dict[str, Any] = {"started": started, **provenance_attrs()}
    if seed is not None:
        entry["seed"] = int(seed)
    if bench is not None and bench.text != prior["bench_yaml"]:
        entry["bench_yaml"] = bench.text
    resumes.append(entry)
    extra["resumes_json"] = json.dumps(resumes)
    if bench is not None and diffs:
        old = json.loads(prior["bench_overrides_json"] or "[]")
        old.append(
            {
                "time": started,
                "differences": diffs,
                "bench_yaml": bench.text,
            }
        )
        extra["bench_overrides_json"] = json.dumps(old)
    clear_consistency_flags(path)  # a writer killed under SWMR leaves them set
    try:
        return RunFileWriter.open_existing(path, extra_attrs=extra)
    except OSError as exc:
        raise StoreError(f"--resume: cannot open {path} for writing ({exc})") from None
