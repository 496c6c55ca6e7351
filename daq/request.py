"""One validation of a whole request, before any instrument is opened or any file written.

A request is a protocol on a bench into an output file, or the continuation of a run file.
:func:`validate_request` sees all of it together: the protocol and bench files (their schemas,
:mod:`protocols.schema` and :mod:`protocols.bench`), the protocol against the bench (the plan,
:func:`daq.engine.make_plan`: amplitude limits, cylinders, travel, rates, Nyquist, the record,
the memory a run asks for), the output path (:func:`daq.store.check_output_path`, with a real
write probe) and, with ``--resume``, the run file (:func:`daq.store.check_resume`: a run file
at all, not complete, the same protocol, the same bench unless ``--accept-bench-change``, the
same scan axes; :func:`daq.store.lock.in_use_by`: no other live writer).

It is the one path of ``run_protocol`` (also ``--dry-run``) and of the window (as the protocol
is typed and before a run starts): whatever it refuses is refused the same way everywhere, in
one line (:class:`RequestError`) naming the file, the line, the field, the value and what is
allowed. The run engine calls the same store helpers again as the file is opened (a second
guard, for what may change in between).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from daq.engine.plan import Plan
from protocols.bench import BenchFile
from protocols.schema import ProtocolFile

__all__ = ["Request", "RequestError", "validate_request"]


class RequestError(ValueError):
    """The request is refused before anything moved; the message is one line."""


@dataclass(frozen=True)
class Request:
    """A validated request: what :class:`daq.engine.RunEngine` is given.

    ``out`` is the run file to write (or, ``resume``, to continue); ``seed`` the simulated
    bench's seed (given, stored in the file, or the bench's); ``bench_changes`` the differences
    from the file's bench accepted with ``accept_bench_change`` (empty otherwise)."""

    protocol: ProtocolFile
    bench: BenchFile
    plan: Plan
    out: Path
    resume: bool = False
    seed: int | None = None
    accept_bench_change: bool = False
    bench_changes: tuple[str, ...] = ()


def _one_line(exc: BaseException) -> str:
    lines = str(exc).strip().splitlines()
    return lines[0] if lines else type(exc).__name__


def validate_request(
    protocol: str | Path | ProtocolFile | None = None,
    bench: str | Path | BenchFile | None = None,
    *,
    out: Path | None = None,
    resume: Path | None = None,
    settings: Sequence[str] = (),
    seed: int | None = None,
    accept_bench_change: bool = False,
    check_output: bool = True,
) -> Request:
    """Validate protocol x bench x output x resume file; :class:`RequestError` when refused.

    Parameters
    ----------
    protocol:
        A protocol file (or the name of a shipped one), an already parsed
        :class:`~protocols.schema.ProtocolFile` (the window's editor), or ``None`` with
        ``resume`` (the file's own protocol).
    bench:
        A bench file, a parsed :class:`~protocols.bench.BenchFile`, or ``None``: the file's
        bench with ``resume``, else the shipped simulated bench.
    out:
        The run file to write, or a folder (the protocol's file name in it); ``None``: the
        protocol's ``output`` pattern. With ``resume`` it must be the same file or ``None``.
    resume:
        The run file to continue.
    settings:
        ``KEY=VALUE`` chain settings of the simulated bench (``run_protocol --set``).
    seed:
        The simulated bench's seed (>= 0); ``None``: the file's (resume) or the bench's.
    accept_bench_change:
        With ``resume``: continue although the bench differs from the file's.
    check_output:
        False skips the output and resume-file checks (the window, as the protocol is
        typed: nothing is about to be written yet).
    """
    from daq.chain_info import chain_spec
    from daq.engine import make_plan
    from daq.store import StoreError, check_output_path, check_resume, stored_request
    from daq.store import stored_seed as _stored_seed
    from daq.store.disk_space import shortfall
    from daq.store.lock import in_use_by
    from protocols.bench import load_bench
    from protocols.runfile import pending_points
    from protocols.schema import load_protocol, output_pattern_problem, shipped_protocols
    from protocols.yamlfile import ConfigError

    if seed is not None and seed < 0:
        raise RequestError(f"--seed: {seed} is negative; give a seed >= 0")
    if resume is not None and out is not None and Path(out) != Path(resume):
        raise RequestError("--out and --resume name different files; give one")
    if protocol is None and resume is None:
        names = ", ".join(shipped_protocols())
        raise RequestError(
            "give a protocol (a file, or a shipped one: "
            f"{names}), or --resume RUN.h5 to continue a run"
        )
    if settings and resume is not None:
        raise RequestError("--set: not with --resume (the run continues on the file's bench)")
    try:
        stored: tuple[ProtocolFile, BenchFile] | None = None
        if resume is not None:
            check_output_path(resume, resume=True)  # a folder, missing, read-only, complete
            if protocol is None or bench is None:
                stored = stored_request(resume)
        pf = _protocol(protocol, load_protocol) if protocol is not None else None
        if isinstance(bench, BenchFile):
            bf: BenchFile | None = bench
        elif bench is not None:
            bf = load_bench(bench, chain_set=tuple(settings))
        else:
            bf = None
        if stored is not None:
            pf, bf = pf or stored[0], bf or stored[1]
        elif bf is None:
            bf = load_bench(None, chain_set=tuple(settings))
        assert pf is not None and bf is not None
        if bf.bench.chain_set:
            chain_spec(bf)  # a bad chain setting is refused before anything runs
        if bf.bench.simulated:
            from daq.connect import sim_world_config

            sim_world_config(bf)  # its faults and integrator, as the run would build them
        plan = make_plan(pf, bf)
        target = _target(pf, out, resume)
        if out is None and resume is None:  # the protocol's pattern names it (the window's
            why = output_pattern_problem(pf.protocol.output)  # editor, as typed: no file read)
            if why is not None:
                raise pf.error(("output",), why)
        changes: list[str] = []
        if check_output:
            if resume is not None:
                changes = check_resume(
                    resume,
                    pf,
                    bf,
                    {d: (plan.amplitudes, plan.cylinders) for d in plan.directions},
                    accept_bench_change=accept_bench_change,
                )
            else:
                check_output_path(target)
            busy = in_use_by(target)
            if busy is not None:
                raise RequestError(busy)
            n_todo = pending_points(resume) if resume is not None else plan.n_points
            short = shortfall(target, n_todo, pf.protocol.acquisition.n_samples())
            if short is not None:
                raise RequestError(short)
        if seed is None and resume is not None and check_output:
            seed = _stored_seed(resume)
        if seed is None and bf.bench.simulation is not None:
            seed = bf.bench.simulation.seed
    except (ConfigError, StoreError) as exc:
        raise RequestError(_one_line(exc)) from None
    except OSError as exc:  # a file that vanished or cannot be read between two checks
        raise RequestError(f"{getattr(exc, 'filename', '') or ''}: {_one_line(exc)}") from None
    return Request(
        protocol=pf,
        bench=bf,
        plan=plan,
        out=target,
        resume=resume is not None,
        seed=seed,
        accept_bench_change=accept_bench_change,
        bench_changes=tuple(changes),
    )


def _protocol(protocol: str | Path | ProtocolFile, load: Any) -> ProtocolFile:
    if isinstance(protocol, ProtocolFile):
        return protocol
    pf: ProtocolFile = load(protocol)
    return pf


def _target(pf: ProtocolFile, out: Path | None, resume: Path | None) -> Path:
    """The run file: the resumed one, ``out``, ``out``/the protocol's name, or the pattern."""
    if resume is not None:
        return Path(resume)
    if out is None:
        return pf.protocol.output_path()
    out = Path(out)
    if out.is_dir():
        return out / pf.protocol.output_path().name  # a folder: the protocol's file name in it
    return out
