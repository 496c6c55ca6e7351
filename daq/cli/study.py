"""``biafc study STUDY.yaml [--scheduler ADDRESS] [--workers N] [--out study.h5]``.

A design study on the DEM (the study file: :mod:`protocols.study`; shipped ones by name,
e.g. ``biafc study example``). Every cell is checked before any task is sent: a bad study
file, a parameter value no chain can have, or an output made from another study is refused
in one line (exit 2). Cells run on ``dask.distributed`` (:mod:`daq.study_runner`): a
LocalCluster of ``--workers`` processes by default (all cores), ``--workers 0`` serially in
this process, ``--scheduler tcp://host:8786`` on a running cluster. Results go into the
output as tasks finish; run the same command again to continue an interrupted study (cells
already in the output are skipped).

Exit status: 0 every cell ran within the accuracy asked for, 4 finished with failed or
inaccurate cells or cells without an error estimate (counted in the last line; a cell whose run
raised is one of the failed), 1 the study failed (a task raised outside its cells), 2 refused,
130 interrupted (the output keeps every finished task; run again to continue).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

from daq.cli.biafc import CliError

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("study", help="study file (YAML), or the name of a shipped study")
    parser.add_argument(
        "--out", type=Path, default=None, help="output (HDF5); default: NAME.h5 here"
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=None,
        help="LocalCluster worker processes (default: the cores); 0: serially in this process",
    )
    parser.add_argument(
        "--scheduler", default=None, help="address of a running Dask scheduler (tcp://host:8786)"
    )
    parser.add_argument(
        "--accept-model-change",
        action="store_true",
        help="continue an output whose cells another DEM model version ran (or one that did "
        "not record it), recording the change in the output",
    )
    parser.add_argument("--dry-run", action="store_true", help="check and count, run nothing")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress display")


def run(args: argparse.Namespace) -> int:
    from analysis.study_cells import (
        StudySetup,
        check_cells,
        check_transit,
        task_cells,
    )
    from daq.store.disk_space import no_margin
    from protocols.study import cell_table, load_study
    from protocols.yamlfile import ConfigError
    from sim_backend.dem.integrators import integrator_error
    from sim_backend.dem.spec import ChainFileError, default_chain_spec, load_chain_spec

    if args.workers is not None and args.workers < 0:
        raise CliError("--workers: 0 (serial) or more")
    if args.workers is not None and args.scheduler is not None:
        raise CliError("--workers and --scheduler: give one (the cluster has its own workers)")
    try:
        sf = load_study(args.study)
    except ConfigError as exc:
        raise CliError(str(exc)) from None
    study = sf.study
    why = integrator_error(study.simulation.integrator)
    if why is not None:  # before: every cell failed at its first model run
        raise CliError(str(sf.error(("simulation", "integrator"), why)))
    try:
        base = load_chain_spec(sf.chain_path) if sf.chain_path else default_chain_spec()
    except ChainFileError as exc:
        raise CliError(str(sf.error(("chain",), str(exc)))) from None
    table = cell_table(study)
    setup = StudySetup(study, base.model_dump_json(), table.names)
    bad = check_cells(setup, table)
    if bad is not None:
        raise CliError(str(sf.error(("parameters", bad[0]), bad[1])))
    too_short = check_transit(setup, table)
    if too_short is not None:
        raise CliError(str(sf.error(("simulation", "duration"), too_short[1])))
    digest = sf.digest(base.to_yaml())
    tasks = task_cells(table.n_cells, study.run.cells_per_task)
    out: Path = args.out if args.out is not None else Path(f"{study.name}.h5")
    if args.dry_run:
        _announce(study, table, tasks, out)
        return 0
    short = no_margin(out)  # an output made on a full disk may be unreadable
    if short is not None:
        raise CliError(short)
    from daq.study_runner import SchedulerUnreachable, connect_scheduler

    client = None
    if args.scheduler is not None:  # before the output is made: refused, exit 2, no file
        try:
            client = connect_scheduler(args.scheduler)
        except SchedulerUnreachable as exc:
            raise CliError(f"--scheduler {exc}") from None
    try:
        return _run_to(args, sf, base.to_yaml(), table, setup, digest, tasks, out, client)
    finally:
        if client is not None:
            client.close()


def _run_to(
    args: argparse.Namespace,
    sf: Any,
    chain_yaml: str,
    table: Any,
    setup: Any,
    digest: str,
    tasks: list[Any],
    out: Path,
    client: Any,
) -> int:
    """Lock, open or create the output, then run (``client``: a connected scheduler's)."""
    study = sf.study
    from analysis.study_cells import spectrum_grid_Hz, stored_names
    from daq.store.lock import FileInUse, RunFileLock
    from protocols.studyfile import StudyFileError, StudyStore
    from sim_backend.dem.versions import model_version

    lock = RunFileLock(out)
    try:
        lock.acquire()
    except FileInUse as exc:
        raise CliError(str(exc)) from None
    try:
        try:
            if out.exists():
                store = StudyStore.open(
                    out, digest=digest, table=table, n_tasks=len(tasks),
                    cells_per_task=study.run.cells_per_task, model_version=model_version(),
                    accept_model_change=args.accept_model_change,
                )  # fmt: skip
            else:
                grid = spectrum_grid_Hz(study) if study.record_spectra else None
                store = StudyStore.create(
                    out, name=study.name, study_yaml=sf.text, digest=digest,
                    chain_yaml=chain_yaml, table=table,
                    directions=study.drive.directions, metric_names=stored_names(study),
                    n_tasks=len(tasks), spectrum_freq_Hz=grid,
                    cells_per_task=study.run.cells_per_task, model_version=model_version(),
                )  # fmt: skip
        except StudyFileError as exc:
            raise CliError(str(exc)) from None
        _announce(study, table, tasks, out)
        return _run(args, setup, table, store, client)
    finally:
        lock.release()


def _announce(study: Any, table: Any, tasks: list[Any], out: Path) -> None:
    n_dirs = len(study.drive.directions)
    print(
        f"study {study.name}: {table.n_cells} cells ({n_dirs} DEM runs each) in "
        f"{len(tasks)} tasks, output {out}",
        file=sys.stderr,
    )


def _compile_first(quiet: bool) -> None:
    """Compile the DEM kernel here, said as run_protocol says it, when none is on disk: the
    workers then load it, where each compiled it silently for 15-20 s while the first ETA
    counted that time as cells' (a second reader: "ETA 01:08" for a study done 1 s later)."""
    from sim_backend.dem.kernel_cache import kernel_cached_on_disk

    if kernel_cached_on_disk():
        return
    from daq.cli import compile_notice
    from daq.cli.warmup import compile_kernel

    if not quiet:
        compile_notice.install()
    compile_kernel()


def _run(args: argparse.Namespace, setup: Any, table: Any, store: Any, client: Any) -> int:
    import numpy as np

    from analysis.study_cells import NO_ESTIMATE, STATUS_FAILED, STATUS_INACCURATE
    from daq.cli.stop_signals import raise_if_stopped
    from daq.progress import ProgressDisplay
    from daq.store.disk_space import DiskFull
    from daq.study_runner import MixedModel, dask_client, n_workers, no_worker_notice, run_study
    from protocols.left_open import exit_leaving_them
    from protocols.studyfile import StudyFileError

    done0 = int(store.done().sum())
    if done0:
        print(f"continuing: {done0} of {table.n_cells} cells done already", file=sys.stderr)
    if done0 < table.n_cells:  # nothing to run, nothing to compile (12 s on an empty cache)
        _compile_first(args.quiet)
    status = "failed"
    error: Exception | None = None
    t0 = time.perf_counter()
    try:
        # tasks end in waves, one per worker: the rate is counted from the end of the first
        workers = 1 if args.workers == 0 else (args.workers or os.cpu_count() or 1)
        if client is not None:
            workers = max(n_workers(client), 1)
        wave = workers * setup.study.run.cells_per_task
        with ProgressDisplay(
            table.n_cells,
            unit="cell",
            label="study",
            quiet=args.quiet,
            start_done=done0,
            steady_after=wave,
        ) as progress:

            def on_task(i: int, res: Any, n_done: int) -> None:
                raise_if_stopped()  # a stop signal Python swallowed where it landed
                progress.update(n_done, detail=f"task {i}")

            if args.workers == 0 or done0 == table.n_cells:  # nothing left: no cluster to
                # start (1.1 s for a study already complete; a second reader)
                summary = run_study(setup, table, store, on_task=on_task)
            elif client is not None:
                with no_worker_notice(client, progress.note):
                    summary = run_study(setup, table, store, client=client, on_task=on_task)
            else:
                workers = args.workers if args.workers is not None else (os.cpu_count() or 1)
                with dask_client(workers) as client:
                    summary = run_study(setup, table, store, client=client, on_task=on_task)
        status = "complete"
    except KeyboardInterrupt:
        status = "incomplete"
        print("the output keeps every finished task; run again to continue", file=sys.stderr)
        raise
    except Exception as exc:
        error = exc
    finally:
        usable = store.broken is None and store.f.id.valid
        codes = store.f["cells/status"][...] if usable else np.zeros(0)
        flagged = np.flatnonzero(codes == STATUS_INACCURATE)
        no_estimate = (
            sum(
                str(m).startswith(NO_ESTIMATE)
                for m in store.f["cells/message"].asstr()[...][flagged]
            )
            if usable and flagged.size
            else 0
        )
        try:
            store.close(status)
        except StudyFileError:
            pass  # store.broken says why
        if store.broken is not None:  # a full disk: the output is left as a killed writer's
            print(f"biafc study: failed: {store.broken}", file=sys.stderr, flush=True)
            exit_leaving_them(1)  # HDF5's clean-up crashes a process that left such a file
    if error is not None:
        first = str(error).splitlines()[0] if str(error) else ""
        if isinstance(error, DiskFull):
            print(f"biafc study: failed: {first}", file=sys.stderr)
        elif isinstance(error, MixedModel):  # the same cluster would fail the same way
            print(
                f"biafc study: failed: {store.path}: {first}; install this biafc-lab on every "
                "worker, then run again to continue",
                file=sys.stderr,
            )
        else:
            print(f"biafc study: failed: {type(error).__name__}: {first}", file=sys.stderr)
            print("the output keeps every finished task; run again to continue", file=sys.stderr)
        return 1
    failed = int(np.sum(codes == STATUS_FAILED))
    inaccurate = int(np.sum(codes == STATUS_INACCURATE)) - no_estimate
    wall = time.perf_counter() - t0
    rate = summary.cells_run / wall if wall > 0 else float("nan")
    print(
        f"study complete: {summary.cells_run} cells run ({summary.cells_skipped} done before) "
        f"in {wall:.1f} s, {rate:.3g} cells/s on {summary.engine}; "
        f"{failed} failed, {inaccurate} above max_error"
        f"{f', {no_estimate} without an error estimate' if no_estimate else ''}; "
        f"written {store.path}",
        file=sys.stderr,
    )
    return 4 if failed or inaccurate or no_estimate else 0
