"""A tiny study (5 cylinders, a 2 ms window, 12 cells in 4 tasks) for the study tests."""

from __future__ import annotations

from pathlib import Path

import pytest

TINY = """\
name: tiny
sampling: grid
parameters:
  diameter: {from: 12 mm, to: 15 mm, count: 3}
  preload: [3 N, 6 N]
  n_cylinders: 5
drive:
  directions: [ltr, rtl]
  amplitudes: [0.5 um, 2 um]
  burst: {cycles: 5}
simulation: {duration: 2 ms, rate: 100 kS/s}
accuracy: {error_estimate: true, max_error: 0.5}
run: {cells_per_task: 3}
"""


@pytest.fixture
def tiny_study(tmp_path: Path) -> Path:
    p = tmp_path / "tiny.yaml"
    p.write_text(TINY)
    return p
