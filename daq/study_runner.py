"""Running a design study's tasks: in this process, on a LocalCluster, or on a Dask cluster.

The engine is ``dask.distributed``: ``workers=0`` runs the tasks one after the other in this
process (debugging, profiling); ``workers=N`` starts a ``LocalCluster`` of N worker processes
(one thread each, and ``cores / N`` numba threads each so that the cores are not
oversubscribed); ``scheduler="tcp://host:8786"`` uses a running cluster (``dask scheduler`` and
``dask worker`` on a few PCs, or dask-jobqueue on SLURM: docs/studies.md).

Tasks (:func:`analysis.study_cells.task_cells`) are submitted a few per worker at a time and
their results written into the output as they finish (``as_completed``): the client holds the
parameter table and at most ``in_flight`` small results, whatever the size of the study. A
worker that dies loses only its tasks, which the scheduler runs again elsewhere; the numbers do
not depend on where or with which other cells a cell runs (bit for bit, ``tests/study``).
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from analysis.study_cells import StudySetup, TaskResult, run_task, task_cells
from daq.store.disk_space import room_for_a_task
from instruments.beside import beside
from protocols.study import CellTable
from protocols.studyfile import StudyStore

__all__ = ["RunSummary", "dask_client", "run_study"]

#: callback after each task is written: (task number, its result, cells done so far)
TaskCallback = Callable[[int, TaskResult, int], None]


@dataclass
class RunSummary:
    """What a run did: tasks and cells run now, cells skipped (done before), wall time (s),
    the summed task time (s, measured inside the tasks) and the engine's name."""

    tasks_run: int
    cells_run: int
    cells_skipped: int
    wall_s: float
    task_s: float
    engine: str


def _numba_threads_env(n_workers: int) -> dict[str, str]:
    cores = os.cpu_count() or 1
    per = str(max(1, cores // max(1, n_workers)))
    return {
        "NUMBA_NUM_THREADS": per,
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
    }


class MixedModel(RuntimeError):
    """A task came back from a worker that runs another model version than the output's."""


class SchedulerUnreachable(Exception):
    """No Dask scheduler answers at the address given (one line: the address, why, what to
    check)."""


#: how long connecting to a ``--scheduler`` may take (s)
CONNECT_S = 10.0
#: how long a cluster may have no worker before the study says so (s)
NO_WORKER_S = 15.0


def connect_scheduler(address: str, timeout_s: float = CONNECT_S) -> Any:
    """A ``distributed.Client`` of the scheduler at ``address``, or :class:`SchedulerUnreachable`
    within about ``timeout_s``: an address nobody listens on timed out only after 30 s, and a
    port where another service answers (the scheduler's own dashboard, 8787) hung for ever or
    ended in a MemoryError from its reply. The connection is made on a thread of its own, so a
    handshake that never ends cannot hold the command."""
    import socket
    from urllib.parse import urlsplit

    from distributed import Client

    hint = "start one (dask scheduler) or check the address, e.g. tcp://host:8786"
    where = urlsplit(address if "://" in address else f"tcp://{address}")
    if where.scheme == "tcp" and where.hostname and where.port:
        try:  # nobody listening: say so at once (distributed retries until its timeout)
            socket.create_connection((where.hostname, where.port), timeout=timeout_s).close()
        except OSError as exc:
            raise SchedulerUnreachable(
                f"{address}: nothing answers there ({exc.strerror or exc}): {hint}"
            ) from None
    box: dict[str, Any] = {}

    def work() -> None:
        try:
            box["client"] = Client(address, timeout=f"{timeout_s}s")
        except BaseException as exc:
            box["error"] = exc

    thread = threading.Thread(target=work, name="biafc-study-connect", daemon=True)
    thread.start()
    thread.join(timeout_s + 5.0)
    if thread.is_alive():
        raise SchedulerUnreachable(
            f"{address}: no Dask scheduler answered within {timeout_s:g} s (is this the "
            f"scheduler's port, not its dashboard's?): {hint}"
        )
    if "error" in box:
        why: BaseException = box["error"]
        first = str(why).splitlines()[0] if str(why) else ""
        raise SchedulerUnreachable(
            f"{address}: no Dask scheduler there ({type(why).__name__}: {first[:200]}): {hint}"
        )
    return box["client"]


def n_workers(client: Any) -> int:
    """Workers connected to ``client``'s scheduler now."""
    return len(client.scheduler_info().get("workers", {}))


@contextmanager
def no_worker_notice(
    client: Any, note: Callable[[str], None], after_s: float = NO_WORKER_S
) -> Iterator[None]:
    """While the block runs, say once per outage when the cluster has had no worker for
    ``after_s`` s (before, the study waited without a word: a scheduler started without
    workers, or its last worker killed)."""
    address = getattr(getattr(client, "scheduler", None), "address", "the scheduler")

    def watch(stop: threading.Event) -> None:
        since: float | None = None
        said = False
        while not stop.wait(1.0):
            try:
                none = n_workers(client) == 0
            except Exception:  # the client closing under us: nothing to say
                return
            now = time.monotonic()
            if not none:
                since, said = None, False
            elif since is None:
                since = now
            elif not said and now - since >= after_s:
                said = True
                note(
                    f"no worker connected to {address} for {after_s:g} s: the study waits; "
                    f"start one (dask worker {address}) or press Ctrl-C (the output keeps every "
                    "finished task)"
                )

    with beside(watch, "biafc-study-workers", join_s=5.0):
        yield


@contextmanager
def dask_client(workers: int) -> Iterator[Any]:
    """A ``distributed.Client`` of a new LocalCluster of ``workers`` processes (closed on exit).
    A running cluster's client comes from :func:`connect_scheduler`."""
    from distributed import Client, LocalCluster

    try:
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            # the scheduler serves its HTTP routes even without a dashboard, on 8787 unless
            # told: another process there printed "Port 8787 is already in use" in the
            # study's terminal
            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
            silence_logs=logging.ERROR,
            env=_numba_threads_env(workers),
            preload=["daq.study_worker"],  # a terminal's Ctrl-C is the study's, not each worker's
        )
    except BaseException:  # interrupted while it starts (Ctrl-C in the first second)
        _forget_half_started()
        raise
    tornado_log = logging.getLogger("tornado.application")
    tornado_log.addFilter(_drop_sync_cancel_error)
    try:
        client = Client(cluster)
        try:
            yield client
        finally:
            with _quiet_closing():
                client.close()
    finally:
        with _quiet_closing():
            cluster.close()
        tornado_log.removeFilter(_drop_sync_cancel_error)


def _drop_sync_cancel_error(record: logging.LogRecord) -> bool:
    """False for ``distributed``'s own error when a Ctrl-C interrupts a blocking call: the
    ``cancel`` callback of ``distributed.utils.sync`` raises ``NameError: cannot access free
    variable 'future'``, and tornado logged its 12-line traceback in the study's terminal
    before the study's clean last line (seen once in CI, 1 run in 5). Every other record
    passes."""
    exc = record.exc_info[1] if record.exc_info else None
    if not isinstance(exc, NameError) or "future" not in str(exc):
        return True
    tb = exc.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    code = tb.tb_frame.f_code if tb is not None else None
    inside = code is not None and code.co_name == "cancel" and "distributed" in code.co_filename
    return not inside


def _forget_half_started() -> None:
    """Close what a LocalCluster interrupted while starting left registered, and forget it:
    ``distributed``'s exit hook closed it again and printed a 28-line "Exception ignored ...
    AssertionError: Status.init" after the study's clean last line (a second reader)."""
    from distributed.deploy.spec import SpecCluster

    for cluster in list(SpecCluster._instances):
        with _quiet_closing(), contextlib.suppress(Exception):
            cluster.close(timeout=5)
        SpecCluster._instances.discard(cluster)


@contextmanager
def _quiet_closing() -> Iterator[None]:
    """While the cluster closes: a task still in flight (an interrupted study) makes
    ``distributed`` log its closed connection at INFO, with a traceback, in the study's
    terminal. Warnings and errors still show."""
    logger = logging.getLogger("distributed")
    level = logger.level
    logger.setLevel(max(level, logging.WARNING))
    try:
        yield
    finally:
        logger.setLevel(level)


def run_study(
    setup: StudySetup,
    table: CellTable,
    store: StudyStore,
    *,
    client: Any | None = None,
    on_task: TaskCallback | None = None,
    in_flight_per_worker: int = 2,
) -> RunSummary:
    """Run the cells not yet in ``store``, task by task (a task with some cells done runs only
    the others: a study continued with another ``run.cells_per_task`` groups its cells anew,
    and no done cell runs twice); write each result as it comes. ``client=None``: serially in
    this process. Raises what a task raised (a bug, not a cell's failure: those are recorded
    per cell)."""
    t0 = time.perf_counter()
    done = store.done()
    skipped = int(done.sum())
    tasks: dict[int, NDArray[np.int64]] = {}
    for i, cells in enumerate(task_cells(table.n_cells, setup.study.run.cells_per_task)):
        left = cells[~done[cells]]
        if left.size:
            tasks[i] = left
    todo = list(tasks)
    n_done = skipped
    task_s = 0.0

    def finish(i: int, res: TaskResult) -> None:
        nonlocal n_done, task_s
        ours = store.model_version
        if ours and res.model_version != ours:  # a cluster's worker on another installation
            raise MixedModel(
                f"worker {res.worker} runs another model ({res.model_version or 'unknown'}) "
                f"than this output's cells ({ours}); its task was not written"
            )
        room_for_a_task(store.path, n_done)
        store.write_task(i, res)
        n_done += int(res.cells.size)
        task_s += res.wall_s
        if on_task is not None:
            on_task(i, res, n_done)

    if client is None:
        for i in todo:
            cells = tasks[i]
            finish(i, run_task(setup, cells, table.values[cells]))
        return RunSummary(
            len(todo), n_done - skipped, skipped, time.perf_counter() - t0, task_s, "serial"
        )

    from distributed import as_completed

    limit = max(1, in_flight_per_worker * max(1, n_workers(client)))
    queue = iter(todo)

    outstanding: dict[str, tuple[int, Any]] = {}

    def submit(i: int) -> Any:
        cells: NDArray[np.int64] = tasks[i]
        fut = client.submit(run_task, setup, cells, table.values[cells], pure=False)
        outstanding[fut.key] = (i, fut)
        return fut

    first = [submit(i) for _, i in zip(range(limit), queue, strict=False)]
    pending = as_completed(first)
    try:
        for fut in pending:
            i, _ = outstanding.pop(fut.key)
            res = fut.result()
            fut.release()
            finish(i, res)
            nxt = next(queue, None)
            if nxt is not None:
                pending.add(submit(nxt))
    except BaseException:
        for _, other in outstanding.values():
            other.cancel()
        raise
    now = n_workers(client)  # at the end: a killed worker is not counted
    engine = f"dask ({now} worker{'' if now == 1 else 's'})"
    return RunSummary(
        len(todo), n_done - skipped, skipped, time.perf_counter() - t0, task_s, engine
    )
