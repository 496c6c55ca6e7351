"""A design study on a full disk (:mod:`daq.store.disk_space`): refused up front when the disk
has no room to spare; stopped before a task's write when it fills, every written task kept and
continued by the same command; a task whose write fails anyway is not marked, and the output is
left as a killed writer's for ``biafc repair``.

Before, a study whose disk filled wrote its output through HDF5's chunk cache, which dropped
what it could not write, and closing that output left it unreadable (even to ``biafc repair``)
while the command said "the output keeps every finished task"; then the process crashed at its
exit (status 139)."""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from analysis.study_cells import TaskResult
from daq.cli.biafc import main
from daq.store import disk_space
from daq.store.repair import repair_run
from protocols.left_open import files_left_open
from protocols.study import cell_table, load_study
from protocols.studyfile import StudyFileError, StudyStore, read_study
from tests.engine.helpers import fake_free_space


def test_a_study_on_a_disk_without_room_is_refused_before_anything_is_written(
    tiny_study: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    fake_free_space(monkeypatch, disk_space.MARGIN_BYTES - 1)
    out = tmp_path / "s.h5"
    assert main(["study", str(tiny_study), "--workers", "0", "--out", str(out), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(out) in err[0] and "16 MB free" in err[0]
    assert not out.exists()


def test_a_disk_that_fills_stops_the_study_every_task_kept_and_the_same_command_completes_it(
    tiny_study: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys, serial_reference
) -> None:
    big = 10**12
    fake_free_space(monkeypatch, big, big, big, disk_space.MARGIN_BYTES - 1)  # room for two tasks
    out = tmp_path / "s.h5"
    assert main(["study", str(tiny_study), "--workers", "0", "--out", str(out), "-q"]) == 1
    err = capsys.readouterr().err
    assert "is full" in err and "6 cell(s) kept" in err and "run the study again" in err
    part = read_study(out)
    assert part.attrs["status"] == "failed" and int(np.sum(part.status != 0)) == 6
    fake_free_space(monkeypatch, big)
    assert main(["study", str(tiny_study), "--workers", "0", "--out", str(out), "-q"]) == 0
    ref, full = read_study(serial_reference), read_study(out)
    for name in ref.metrics:
        assert np.array_equal(ref.metrics[name], full.metrics[name], equal_nan=True), name


def test_a_task_whose_write_fails_is_not_marked_and_the_output_is_left_for_repair(
    tiny_study: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, serial_reference: Path
) -> None:
    ref = read_study(serial_reference)
    out = tmp_path / "s.h5"
    shutil.copy(serial_reference, out)  # the reference's cells, written again task by task
    with h5py.File(out, "r+") as f:
        f["cells/status"][...] = 0
        digest = str(f.attrs["study_digest"])
    store = StudyStore.open(out, digest=digest, table=cell_table(load_study(tiny_study).study))

    def task(cells: list[int]) -> TaskResult:
        idx = np.asarray(cells)
        metrics = {k: v[idx] for k, v in ref.metrics.items()}
        return TaskResult(cells=idx, metrics=metrics, status=ref.status[idx], wall_s=0.1)

    store.write_task(0, task([0, 1, 2]))
    real_flush = h5py.Dataset.flush

    def full(self: h5py.Dataset) -> None:  # the second task's records meet a full disk
        raise RuntimeError("Unable to flush dataset (file write failed: errno = 28)")

    monkeypatch.setattr(h5py.Dataset, "flush", full)
    with pytest.raises(StudyFileError, match=r"task 1 could not be written.*biafc repair"):
        store.write_task(1, task([3, 4, 5]))
    monkeypatch.setattr(h5py.Dataset, "flush", real_flush)
    with pytest.raises(StudyFileError):
        store.write_task(2, task([6, 7, 8]))  # no more writes once broken
    store.close("failed")  # leaves the file alone, as a killed writer would
    assert store.f.id.valid
    assert files_left_open() == (str(out),)  # the process must end without HDF5's clean-up
    store.f.close()
    report = repair_run(out)
    after = read_study(out)
    assert report.status_after == "incomplete"
    assert list(np.flatnonzero(after.status != 0)) == [0, 1, 2]
