"""A design study of 2000 cheap cells, serially and on a 2-worker LocalCluster, in one run.

The study (:data:`STUDY`): 20 diameters x 25 pre-compressions x 4 amplitudes of a 6-cylinder
chain, both directions, a 2 ms window at 100 kS/s, 5-cycle bursts, no error estimate: 4000
trajectories, about 3 ms of work per cell. Cells are grouped 40 to a task (10 chains of 4
amplitudes: 8 lanes per batched sweep).

Reported: cells/s serially (``--workers 0``: one process, numba threads over the batch's lane
chunks) and on the LocalCluster (2 processes, one thread and ``cores / 2`` numba threads each;
the cluster is started and every worker has loaded the compiled kernel before the clock starts),
their ratio, and the distributed overhead per task: the worker time not spent inside a task,
``(workers x wall - sum of task times) / tasks``, against the mean task time (target under 5 %).
It includes scheduling, transfers, writing into the output and the last tasks' tail, when one
worker waits for the other. The two outputs are compared bit for bit (``identical``).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

STUDY = """\
name: bench
sampling: grid
parameters:
  diameter: {from: 12 mm, to: 15.5 mm, count: 20}
  preload: {from: 2 N, to: 10 N, count: 25}
  n_cylinders: 6
drive:
  directions: [ltr, rtl]
  amplitudes: [0.25 um, 0.5 um, 1 um, 2 um]
  burst: {cycles: 5}
simulation: {duration: 2 ms, rate: 100 kS/s}
accuracy: {error_estimate: false}
run: {cells_per_task: 40}
"""
WORKERS = 2


def _setup() -> tuple[Any, Any, Any]:
    from analysis.study_cells import StudySetup
    from protocols.study import cell_table, parse_study
    from sim_backend.dem.spec import default_chain_spec

    sf = parse_study(STUDY, "benchmarks/study.py")
    table = cell_table(sf.study)
    base = default_chain_spec()
    return sf, table, StudySetup(sf.study, base.model_dump_json(), table.names)


def _warm() -> int:
    """Import the task's modules and load the compiled kernel in this process: one cell."""
    from analysis.study_cells import run_task

    _, table, setup = _setup()
    run_task(setup, np.arange(1), table.values[:1])
    return os.getpid()


def _one(folder: Path, name: str, client: Any | None) -> dict[str, Any]:
    from analysis.study_cells import stored_names, task_cells
    from daq.study_runner import run_study
    from protocols.studyfile import StudyStore, read_study
    from sim_backend.dem.spec import default_chain_spec
    from sim_backend.dem.versions import model_version

    sf, table, setup = _setup()
    base = default_chain_spec()
    n_tasks = len(task_cells(table.n_cells, sf.study.run.cells_per_task))
    out = folder / f"{name}.h5"
    store = StudyStore.create(
        out, name="bench", study_yaml=STUDY, digest=sf.digest(base.to_yaml()),
        chain_yaml=base.to_yaml(), table=table, directions=sf.study.drive.directions,
        metric_names=stored_names(sf.study), n_tasks=n_tasks, model_version=model_version(),
    )  # fmt: skip
    t0 = time.perf_counter()
    summary = run_study(setup, table, store, client=client)
    wall = time.perf_counter() - t0
    store.close("complete")
    data = read_study(out)
    return {
        "cells": summary.cells_run,
        "tasks": summary.tasks_run,
        "wall_s": wall,
        "task_s": summary.task_s,
        "cells_per_s": summary.cells_run / wall,
        "metrics": data.metrics,
        "status": data.status,
    }


def _same(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return all(
        np.array_equal(a["metrics"][k], b["metrics"][k], equal_nan=True) for k in a["metrics"]
    ) and bool(np.array_equal(a["status"], b["status"]))


def run() -> dict[str, Any]:
    import numba

    from daq.study_runner import dask_client

    _warm()
    threads = numba.get_num_threads()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        serial = _one(folder, "serial", None)
        numba.set_num_threads(1)
        try:
            serial1 = _one(folder, "serial1", None)
        finally:
            numba.set_num_threads(threads)
        with dask_client(WORKERS) as client:
            client.run(_warm)  # every worker has its kernel and modules before the clock starts
            dist = _one(folder, "dask", client)
    identical = _same(serial, dist) and _same(serial1, dist)
    best_serial = max(serial["cells_per_s"], serial1["cells_per_s"])
    ok = int(np.sum(dist["status"] == 1))
    mean_task = dist["task_s"] / dist["tasks"]
    overhead = (WORKERS * dist["wall_s"] - dist["task_s"]) / dist["tasks"]
    rows = [
        {"engine": f"serial, {threads} numba threads", "cells": serial["cells"],
         "tasks": serial["tasks"], "wall_s": serial["wall_s"],
         "cells_per_s": serial["cells_per_s"], "mean_task_s": serial["task_s"] / serial["tasks"]},
        {"engine": "serial, 1 numba thread", "cells": serial1["cells"],
         "tasks": serial1["tasks"], "wall_s": serial1["wall_s"],
         "cells_per_s": serial1["cells_per_s"],
         "mean_task_s": serial1["task_s"] / serial1["tasks"]},
        {"engine": f"LocalCluster ({WORKERS} workers)", "cells": dist["cells"],
         "tasks": dist["tasks"], "wall_s": dist["wall_s"], "cells_per_s": dist["cells_per_s"],
         "mean_task_s": mean_task},
    ]  # fmt: skip
    return {
        "cells": serial["cells"],
        "cells_ok": ok,
        "serial_cells_per_s": serial["cells_per_s"],
        "serial_1thread_cells_per_s": serial1["cells_per_s"],
        "dask_cells_per_s": dist["cells_per_s"],
        "dask_over_serial": dist["cells_per_s"] / serial["cells_per_s"],
        "dask_over_best_serial": dist["cells_per_s"] / best_serial,
        "mean_task_s": mean_task,
        "overhead_per_task_s": overhead,
        "overhead_fraction": overhead / mean_task,
        "overhead_target": 0.05,
        "identical": bool(identical),
        "workers": WORKERS,
        "cpus": os.cpu_count(),
        "table": rows,
    }
