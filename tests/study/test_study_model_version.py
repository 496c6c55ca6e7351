"""A study output records the model version that ran its cells, and is not continued by
another: cells of two DEM kernels (or two mode computations) would mix in one output."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from analysis.study_cells import StudySetup, TaskResult, stored_names, task_cells
from daq.cli.biafc import main
from daq.study_runner import MixedModel, run_study
from protocols.study import cell_table, load_study
from protocols.studyfile import StudyFileError, StudyStore, read_study
from sim_backend.dem import versions
from sim_backend.dem.beam import MODES_VERSION
from sim_backend.dem.kernel import NUMERICS_VERSION
from sim_backend.dem.spec import default_chain_spec


def test_the_model_version_names_the_kernel_and_the_modes() -> None:
    v = versions.model_version()
    assert NUMERICS_VERSION in v and MODES_VERSION in v


def test_a_study_output_records_the_model_version(serial_reference: Path) -> None:
    with h5py.File(serial_reference, "r") as f:
        assert f.attrs["model_version"] == versions.model_version()


def test_another_model_version_is_not_continued(
    serial_reference: Path, tiny_study: Path, tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    out = tmp_path / "made.h5"
    shutil.copy(serial_reference, out)
    with h5py.File(out, "r+") as f:  # cells left to run: a continue would run them
        f["cells/status"][6:] = 0
    before = out.read_bytes()
    versions_model = versions.model_version()
    monkeypatch.setattr(versions, "model_version", lambda: "kernel 5: another; modes 2")
    assert main(["study", str(tiny_study), "--workers", "0", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert "another model" in err and "kernel 5: another" in err and NUMERICS_VERSION in err
    assert "--accept-model-change" in err
    assert out.read_bytes() == before
    # accepted: continued, the change recorded, the output's version now this one
    args = ["study", str(tiny_study), "--workers", "0", "--out", str(out), "-q"]
    assert main([*args, "--accept-model-change"]) == 0
    with h5py.File(out, "r") as f:
        assert f.attrs["model_version"] == "kernel 5: another; modes 2"
        (change,) = json.loads(f.attrs["model_changes_json"])
    assert change["from"] == versions_model and change["to"] == "kernel 5: another; modes 2"
    assert change["cells_done"] == 6
    assert np.all(read_study(out).status == 1)


def test_a_complete_output_of_another_model_is_still_read_by_its_command(
    serial_reference: Path, tiny_study: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A reviewer: a complete output made before the model version was recorded was refused
    by the command that made it, where nothing is left to run and nothing can mix."""
    out = tmp_path / "complete.h5"
    shutil.copy(serial_reference, out)
    with h5py.File(out, "r+") as f:
        del f.attrs["model_version"]
    monkeypatch.setattr(versions, "model_version", lambda: "kernel 5: another; modes 2")
    assert main(["study", str(tiny_study), "--workers", "0", "--out", str(out), "-q"]) == 0


def test_an_output_that_did_not_record_its_model_version_is_not_continued(
    serial_reference: Path, tiny_study: Path, tmp_path: Path
) -> None:
    out = tmp_path / "old.h5"
    shutil.copy(serial_reference, out)
    with h5py.File(out, "r+") as f:
        del f.attrs["model_version"]
    sf = load_study(tiny_study)
    table = cell_table(sf.study)
    digest = sf.digest(default_chain_spec().to_yaml())
    with h5py.File(out, "r+") as f:  # cells left to run
        f["cells/status"][6:] = 0
    with pytest.raises(StudyFileError, match="made before study outputs recorded their model"):
        StudyStore.open(out, digest=digest, table=table, model_version=versions.model_version())


def test_a_task_from_a_worker_on_another_model_is_not_written(
    tiny_study: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    sf = load_study(tiny_study)
    table = cell_table(sf.study)
    base = default_chain_spec()
    setup = StudySetup(sf.study, base.model_dump_json(), table.names)
    store = StudyStore.create(
        tmp_path / "mixed.h5", name="tiny", study_yaml=sf.text,
        digest=sf.digest(base.to_yaml()), chain_yaml=base.to_yaml(), table=table,
        directions=sf.study.drive.directions, metric_names=stored_names(sf.study),
        n_tasks=len(task_cells(table.n_cells, sf.study.run.cells_per_task)),
        model_version=versions.model_version(),
    )  # fmt: skip

    class Future:
        key = "k"

        def __init__(self, res: TaskResult) -> None:
            self.res = res

        def result(self) -> TaskResult:
            return self.res

        def release(self) -> None:
            pass

        def cancel(self) -> None:
            pass

    class Client:  # a cluster whose worker runs another installation
        def submit(self, fn: Any, setup: Any, cells: Any, values: Any, pure: bool) -> Future:
            k = len(cells)
            names = stored_names(sf.study)
            return Future(TaskResult(
                cells=np.asarray(cells), metrics={n: np.zeros(k) for n in names},
                status=np.ones(k, np.int8), worker="lab-pc:1", model_version="kernel 3; modes 1",
            ))  # fmt: skip

    import distributed

    import daq.study_runner as runner

    class Pending(list):  # type: ignore[type-arg]
        def add(self, f: Future) -> None:
            self.append(f)

    monkeypatch.setattr(distributed, "as_completed", Pending)
    monkeypatch.setattr(runner, "n_workers", lambda c: 1)
    with pytest.raises(MixedModel, match="lab-pc:1 runs another model"):
        run_study(setup, table, store, client=Client())
    store.close("failed")
    assert not np.any(read_study(tmp_path / "mixed.h5").status)


def test_a_worker_on_another_model_ends_the_study_in_one_line(
    tiny_study: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    """A reviewer: it printed "failed: MixedModel: ..." and "run again to continue", which
    fails the same way on the same cluster, without naming the output."""
    from types import SimpleNamespace

    import analysis.study_cells

    worker = SimpleNamespace(model_version=lambda: "kernel 3; modes 1")
    monkeypatch.setattr(analysis.study_cells, "versions", worker)  # where the tasks run
    out = tmp_path / "s.h5"
    assert main(["study", str(tiny_study), "--workers", "0", "--out", str(out), "-q"]) == 1
    err = capsys.readouterr().err.strip().splitlines()[1:]  # after the study's announcement
    assert len(err) == 1, err
    assert err[0].startswith(f"biafc study: failed: {out}: worker ") and "kernel 3" in err[0]
    assert "install this biafc-lab on every worker" in err[0]
    assert not np.any(read_study(out).status)
