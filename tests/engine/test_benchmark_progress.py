"""``python -m benchmarks`` shows its progress through the shared display (daq.progress)."""

from __future__ import annotations

import types
from pathlib import Path

import pytest

import benchmarks.__main__ as runner


def test_benchmark_runner_progress(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    fake = types.SimpleNamespace(run=lambda: {"wall_s": 0.25})
    monkeypatch.setattr(runner, "available", lambda: ["tiny", "small"])
    monkeypatch.setattr(runner.importlib, "import_module", lambda name: fake)
    monkeypatch.setattr(runner, "RESULTS", tmp_path)
    assert runner.main(["tiny", "small"]) == 0
    captured = capsys.readouterr()
    assert "== tiny" in captured.out and "== small" in captured.out
    assert "benchmark 2/2: small done" in captured.err
    assert (tmp_path / "small.json").exists()
    assert runner.main(["tiny", "nope"]) == 2  # refused before anything runs
    assert "== tiny" not in capsys.readouterr().out


def test_new_results_go_to_an_untracked_folder_beside_the_reference(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The recorded results stay untouched; the new run is printed against them."""
    ref, runs = tmp_path / "results", tmp_path / "runs"
    ref.mkdir()
    (ref / "tiny.json").write_text('{"wall_s": 0.5, "note": "kept"}\n')
    fake = types.SimpleNamespace(run=lambda: {"wall_s": 0.25})
    monkeypatch.setattr(runner, "available", lambda: ["tiny"])
    monkeypatch.setattr(runner.importlib, "import_module", lambda name: fake)
    monkeypatch.setattr(runner, "RESULTS", runs)
    monkeypatch.setattr(runner, "REFERENCE", ref)
    assert runner.main(["tiny"]) == 0
    assert (ref / "tiny.json").read_text() == '{"wall_s": 0.5, "note": "kept"}\n'
    assert (runs / "tiny.json").exists()
    assert "wall_s: 0.25 (reference 0.5, new/ref 0.5)" in capsys.readouterr().out


def test_results_folders() -> None:
    assert runner.REFERENCE.name == "results" and runner.RESULTS.name == "runs"
    assert "benchmarks/runs/" in (Path(runner.__file__).parents[1] / ".gitignore").read_text()
