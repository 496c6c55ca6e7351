"""A study compiles the DEM kernel first, and says so, when none is on disk (a second reader:
silent for 17 s, then "ETA 01:08" for a study that ended a second later)."""

from __future__ import annotations

from pathlib import Path

import pytest

import daq.study_runner
from daq.cli import warmup
from daq.cli.biafc import main
from sim_backend.dem import kernel_cache


@pytest.mark.parametrize("on_disk", [False, True])
def test_a_study_compiles_the_kernel_before_its_first_task_only_when_none_is_on_disk(
    tiny_study: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    on_disk: bool,
) -> None:
    order: list[str] = []
    monkeypatch.setattr(kernel_cache, "kernel_cached_on_disk", lambda: on_disk)
    monkeypatch.setattr(warmup, "compile_kernel", lambda chain=None: order.append("c"))
    real = daq.study_runner.run_study

    def run_study(*a, **k):  # type: ignore[no-untyped-def]
        order.append("study")
        return real(*a, **k)

    monkeypatch.setattr(daq.study_runner, "run_study", run_study)
    assert main(["study", str(tiny_study), "--workers", "0", "--out", str(tmp_path / "s.h5")]) == 0
    assert order == (["study"] if on_disk else ["c", "study"])
