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
