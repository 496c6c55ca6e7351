"""Running a study: the same numbers serially, on a LocalCluster, after a killed worker and
after a resume; a cell's numbers do not depend on the cells that share its batch."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from analysis.study_cells import (
    StudySetup,
    run_task,
    stored_names,
    task_cells,
)
from daq.cli.biafc import main
from daq.study_runner import dask_client, run_study
from protocols.study import cell_table, load_study
from protocols.studyfile import StudyStore, read_study
from sim_backend.dem.spec import default_chain_spec
from sim_backend.dem.versions import model_version


def _setup(path: Path) -> tuple[Any, Any, Any, str]:
    sf = load_study(path)
    table = cell_table(sf.study)
    base = default_chain_spec()
    setup = StudySetup(sf.study, base.model_dump_json(), table.names)
    return sf, table, setup, sf.digest(base.to_yaml())


def _store(path: Path, out: Path) -> tuple[Any, Any, Any]:
    sf, table, setup, digest = _setup(path)
    n_tasks = len(task_cells(table.n_cells, sf.study.run.cells_per_task))
    store = StudyStore.create(
        out, name=sf.study.name, study_yaml=sf.text, digest=digest,
        chain_yaml=default_chain_spec().to_yaml(), table=table,
        directions=sf.study.drive.directions, metric_names=stored_names(sf.study),
        n_tasks=n_tasks, model_version=model_version(),
    )  # fmt: skip
    return setup, table, store


def _same(a: Path, b: Path) -> None:
    ra, rb = read_study(a), read_study(b)
    assert ra.metrics.keys() == rb.metrics.keys()
    for name in ra.metrics:
        assert np.array_equal(ra.metrics[name], rb.metrics[name], equal_nan=True), name
    assert np.array_equal(ra.status, rb.status)


@pytest.fixture(scope="module")
def client() -> Any:
    with dask_client(2) as c:
        yield c


def test_a_cell_does_not_depend_on_the_cells_in_its_batch(tiny_study: Path) -> None:
    _, table, setup, _ = _setup(tiny_study)
    everything = np.arange(table.n_cells)
    together = run_task(setup, everything, table.values)
    for cells in ([5], [7, 2], [11, 0, 6]):
        idx = np.asarray(cells)
        alone = run_task(setup, idx, table.values[idx])
        for name, arr in alone.metrics.items():
            assert np.array_equal(arr, together.metrics[name][idx], equal_nan=True), name


def test_two_worker_processes_give_the_serial_result_bit_for_bit(
    tiny_study: Path, serial_reference: Path, client: Any, tmp_path: Path
) -> None:
    setup, table, store = _store(tiny_study, tmp_path / "dask.h5")
    summary = run_study(setup, table, store, client=client)
    workers = set(store.f["tasks/worker"].asstr()[...])
    store.close("complete")
    assert summary.cells_run == table.n_cells and summary.engine == "dask (2 workers)"
    assert len(workers) == 2 and f"{os.uname().nodename}:{os.getpid()}" not in workers
    _same(serial_reference, tmp_path / "dask.h5")


def test_a_killed_worker_loses_only_its_tasks_and_the_study_completes_the_same(
    tiny_study: Path, serial_reference: Path, client: Any, tmp_path: Path
) -> None:
    setup, table, store = _store(tiny_study, tmp_path / "killed.h5")
    killed: list[int] = []
    lost: list[int] = []

    def kill_one(i: int, res: Any, n_done: int) -> None:
        if killed:
            return
        # what each worker holds of this study: tasks running or queued there, and results
        # finished there but not yet written (under load the workers may have run every task
        # in flight before this callback; a result in a dead worker's memory is lost too and
        # run again). The result in hand came from another worker: the victim holds no part
        # of it, so whatever it holds must be rerun.
        live = set(client.futures)
        held: dict[str, set[str]] = {w: set() for w in client.scheduler_info()["workers"]}
        for table_ in (client.processing(), client.has_what()):
            for w, keys in table_.items():
                held.setdefault(w, set()).update(k for k in keys if k in live)
        pids = client.run(os.getpid)
        others = [w for w in pids if not res.worker.endswith(f":{pids[w]}")]
        victim = max(others, key=lambda w: len(held.get(w, ())))
        lost.append(len(held.get(victim, ())))
        os.kill(pids[victim], signal.SIGKILL)
        killed.append(pids[victim])

    summary = run_study(setup, table, store, client=client, on_task=kill_one)
    store.close("complete")
    assert killed and summary.cells_run == table.n_cells
    assert lost[0] >= 1  # the killed worker held a task: it was run again elsewhere
    _same(serial_reference, tmp_path / "killed.h5")
    # the nanny brings a worker back for the next test
    deadline = time.monotonic() + 20
    while len(client.scheduler_info()["workers"]) < 2 and time.monotonic() < deadline:
        time.sleep(0.1)


def test_resume_skips_done_cells_and_ends_with_the_same_result(
    tiny_study: Path, serial_reference: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "resumed.h5"
    setup, table, store = _store(tiny_study, out)

    def stop_after_two(i: int, res: Any, n_done: int) -> None:
        if n_done >= 6:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_study(setup, table, store, on_task=stop_after_two)
    store.close("incomplete")
    assert int((read_study(out).status != 0).sum()) == 6
    ran: list[np.ndarray] = []
    store = StudyStore.open(out, digest=_setup(tiny_study)[3], table=table)
    summary = run_study(setup, table, store, on_task=lambda i, r, n: ran.append(r.cells))
    store.close("complete")
    assert summary.cells_skipped == 6 and summary.cells_run == 6
    assert sorted(np.concatenate(ran)) == list(range(6, 12))
    _same(serial_reference, out)
    # the command line resumes too: nothing left to run
    assert main(["study", str(tiny_study), "--workers", "0", "--out", str(out), "-q"]) == 0
    assert "12 done before" in capsys.readouterr().err


def test_an_output_of_another_study_is_not_continued(
    tiny_study: Path, serial_reference: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    other = tmp_path / "other.yaml"
    other.write_text(tiny_study.read_text().replace("[3 N, 6 N]", "[3 N, 7 N]"))
    before = serial_reference.read_bytes()
    assert main(["study", str(other), "--workers", "0", "--out", str(serial_reference)]) == 2
    err = capsys.readouterr().err
    assert "made from another study" in err and len(err.strip().splitlines()) == 1
    assert serial_reference.read_bytes() == before


@pytest.mark.parametrize(("first", "then"), [(6, 1), (6, 5)])
def test_a_study_continued_with_another_cells_per_task_runs_each_cell_once_the_same(
    tiny_study: Path,
    serial_reference: Path,
    tmp_path: Path,
    first: int,
    then: int,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``run.cells_per_task`` edited between runs (the digest leaves ``run`` out, so the output
    is continued): before, 6 -> 1 wrote past the end of /tasks (IndexError at every continue),
    and 6 -> 5 reran task 0 whole, done cells included ("cell 244/240")."""
    import h5py

    text = tiny_study.read_text()
    tiny_study.write_text(text.replace("cells_per_task: 3", f"cells_per_task: {first}"))
    out = tmp_path / "s.h5"
    assert main(["study", str(tiny_study), "--workers", "0", "--out", str(out), "-q"]) == 0
    with h5py.File(out, "r+") as f:  # as if stopped after cells 0-3: the rest not run
        f["cells/status"][4:] = 0
        for name in f["metrics"]:
            f["metrics"][name][4:] = np.nan
    tiny_study.write_text(text.replace("cells_per_task: 3", f"cells_per_task: {then}"))
    capsys.readouterr()
    assert main(["study", str(tiny_study), "--workers", "0", "--out", str(out), "-q"]) == 0
    err = capsys.readouterr().err
    assert "study complete: 8 cells run (4 done before)" in err, err
    _same(serial_reference, out)
    with h5py.File(out, "r") as f:
        n_tasks = len(task_cells(12, then))
        assert f["tasks/wall_s"].shape == (n_tasks,)
        assert f["tasks"].attrs["cells_per_task"] == then
        assert f["tasks_earlier/0"].attrs["cells_per_task"] == first
        assert f["tasks_earlier/0/wall_s"].shape == (2,)
        ran = np.isfinite(f["tasks/wall_s"][...])
        assert ran.sum() == len({c // then for c in range(4, 12)})


def test_a_complete_output_starts_no_cluster(
    tiny_study: Path, serial_reference: Path, tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    """A second reader: a study already complete still started a LocalCluster (1.6 s against
    0.5 s) to run 0 cells."""
    import shutil

    import daq.study_runner

    def no_cluster(workers: int) -> Any:
        raise AssertionError("a cluster was started")

    monkeypatch.setattr(daq.study_runner, "dask_client", no_cluster)
    import daq.cli.study

    def no_compile(quiet: bool) -> None:
        raise AssertionError("the kernel was compiled for 0 cells")

    monkeypatch.setattr(daq.cli.study, "_compile_first", no_compile)
    out = tmp_path / "complete.h5"
    shutil.copy(serial_reference, out)
    assert main(["study", str(tiny_study), "--out", str(out), "-q"]) == 0
    assert "0 cells run (12 done before)" in capsys.readouterr().err
