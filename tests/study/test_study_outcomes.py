"""How a study ends: exit 4 with failed or inaccurate cells, 1 when a task raises, 130 on
Ctrl-C (the finished tasks kept, the next run continues)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

import daq.study_runner
from analysis.study_cells import STATUS_FAILED, STATUS_INACCURATE, STATUS_OK
from daq.cli.biafc import main
from protocols.studyfile import read_study

from .conftest import TINY


def test_impossible_cells_fail_alone_and_the_study_exits_4(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = TINY.replace(
        "  diameter: {from: 12 mm, to: 15 mm, count: 3}\n  preload: [3 N, 6 N]\n",
        "  alpha: [0.1, 1.9]\n",
    ).replace("amplitudes: [0.5 um, 2 um]", "amplitudes: [2 um]")
    study = tmp_path / "s.yaml"
    study.write_text(text)
    out = tmp_path / "s.h5"
    assert main(["study", str(study), "--workers", "0", "--out", str(out), "-q"]) == 4
    assert "1 failed, 0 above max_error" in capsys.readouterr().err
    data = read_study(out)
    assert list(data.status) == [STATUS_OK, STATUS_FAILED]
    assert "impossible" in data.messages[1] and data.messages[0] == ""
    assert np.isnan(data.metrics["asymmetry_ratio"][1])
    assert np.isfinite(data.metrics["asymmetry_ratio"][0])


def test_cells_above_the_accuracy_asked_for_are_flagged_and_exit_4(tmp_path: Path) -> None:
    study = tmp_path / "s.yaml"
    study.write_text(TINY.replace("max_error: 0.5", "max_error: 1e-12"))
    out = tmp_path / "s.h5"
    assert main(["study", str(study), "--workers", "0", "--out", str(out), "-q"]) == 4
    data = read_study(out)
    assert np.all(data.status == STATUS_INACCURATE)
    assert np.all(np.isfinite(data.metrics["transmission_ltr"]))  # numbers kept, flagged


def test_a_cell_without_an_error_estimate_is_said_so_not_counted_above_max_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A step of 5 us, stable, whose 2h of the step-doubling estimate is not on the stiffest
    chains: their estimate is NaN. Before, they were counted "above max_error"."""
    study = tmp_path / "s.yaml"
    study.write_text(TINY.replace("rate: 100 kS/s}", "rate: 100 kS/s, dt: 5 us}"))
    out = tmp_path / "s.h5"
    assert main(["study", str(study), "--workers", "0", "--out", str(out), "-q"]) == 4
    last = capsys.readouterr().err.strip().splitlines()[-1]
    data = read_study(out)
    nan = ~np.isfinite(data.metrics["error_estimate_ltr"])
    n = int(nan.sum())
    assert 0 < n < data.n_cells
    assert f"0 failed, 0 above max_error, {n} without an error estimate" in last, last
    assert np.all(data.status[nan] == STATUS_INACCURATE)
    for msg in data.messages[nan]:
        assert msg == "no error estimate (ltr, rtl: the step 2h is unstable)", msg
    assert np.all(data.status[~nan] == STATUS_OK) and set(data.messages[~nan]) == {""}


def test_a_cell_whose_run_raises_anything_fails_alone_and_the_study_exits_4(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Not a ValueError or ArithmeticError (a bug, a numba error) in one chain's run: before,
    it stopped the whole study (exit 1), and every rerun stopped at the same cell."""
    import analysis.study_cells as sc

    real = sc._run_group

    def crashing(setup: Any, params: dict[str, float], *args: Any) -> Any:
        if params.get("preload") == 6.0:
            raise RuntimeError("injected: the kernel crashed\nsecond line")
        return real(setup, params, *args)

    monkeypatch.setattr(sc, "_run_group", crashing)
    study = tmp_path / "s.yaml"
    study.write_text(TINY)
    out = tmp_path / "s.h5"
    assert main(["study", str(study), "--workers", "0", "--out", str(out), "-q"]) == 4
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert "12 cells run" in last and "6 failed, 0 above max_error" in last, last
    data = read_study(out)
    assert data.attrs["status"] == "complete"
    bad = data.parameters["preload"] == 6.0
    assert np.all(data.status[bad] == STATUS_FAILED)
    assert set(data.messages[bad]) == {"RuntimeError: injected: the kernel crashed"}
    assert np.all(data.status[~bad] == STATUS_OK)
    assert np.all(np.isnan(data.metrics["transmission_ltr"][bad]))


def test_a_task_that_raises_fails_the_study_with_exit_1(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def broken(*args: Any) -> Any:
        raise RuntimeError("a bug in the task")

    monkeypatch.setattr(daq.study_runner, "run_task", broken)
    study = tmp_path / "s.yaml"
    study.write_text(TINY)
    out = tmp_path / "s.h5"
    assert main(["study", str(study), "--workers", "0", "--out", str(out), "-q"]) == 1
    assert "RuntimeError: a bug in the task" in capsys.readouterr().err
    assert read_study(out).attrs["status"] == "failed"


def test_ctrl_c_exits_130_keeps_the_finished_tasks_and_the_next_run_completes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, serial_reference: Path
) -> None:
    real = daq.study_runner.run_task
    calls: list[int] = []

    def interrupted(*args: Any) -> Any:
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(*args)

    monkeypatch.setattr(daq.study_runner, "run_task", interrupted)
    study = tmp_path / "tiny.yaml"
    study.write_text(TINY)
    out = tmp_path / "s.h5"
    assert main(["study", str(study), "--workers", "0", "--out", str(out), "-q"]) == 130
    data = read_study(out)
    assert data.attrs["status"] == "incomplete" and int((data.status != 0).sum()) == 6
    monkeypatch.setattr(daq.study_runner, "run_task", real)
    assert main(["study", str(study), "--workers", "0", "--out", str(out), "-q"]) == 0
    done, ref = read_study(out), read_study(serial_reference)
    assert done.attrs["status"] == "complete"
    for name in ref.metrics:
        assert np.array_equal(done.metrics[name], ref.metrics[name], equal_nan=True), name
