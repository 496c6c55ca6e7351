"""A tiny study (5 cylinders, a 2 ms window, 12 cells in 4 tasks) for the study tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
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


@pytest.fixture(scope="session")
def serial_reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny study run serially (``--workers 0``): the reference output."""
    from daq.cli.biafc import main
    from protocols.studyfile import read_study

    d = tmp_path_factory.mktemp("ref")
    (d / "tiny.yaml").write_text(TINY)
    out = d / "serial.h5"
    assert main(["study", str(d / "tiny.yaml"), "--workers", "0", "--out", str(out), "-q"]) == 0
    data = read_study(out)
    assert np.all(data.status == 1) and data.attrs["status"] == "complete"
    assert np.all(np.isfinite(data.metrics["asymmetry_ratio"]))
    assert np.all(data.metrics["error_estimate_ltr"] < 0.5)
    return out
