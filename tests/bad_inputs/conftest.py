"""Sources the bad-input cases are cut from: a small complete run file and a foreign HDF5."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from protocols.runfile import RunFileWriter, ScanSpec
from tests.engine.helpers import chain_info


def write_small_run(path: Path) -> Path:
    """A complete run file: one direction, 2 amplitudes x 3 cylinders x 400 samples."""
    t = np.arange(400) / 200e3
    spec = ScanSpec("ltr", np.array([0.5e-6, 3e-6]), "m", np.array([1, 8, 16], np.int32), t,
                    8920.0, cycles=21.0, drive_units="m")  # fmt: skip
    w = RunFileWriter.create(path, backend="sim", chain=chain_info(), scans=[spec],
                             protocol_yaml="name: smoke\n", bench_yaml="name: sim\n")  # fmt: skip
    rng = np.random.default_rng(0)
    for a in range(2):
        for c in range(3):
            w.write_point("ltr", a, c, rng.normal(size=t.size), np.sin(2e4 * t))
    w.close("complete")
    return path


def make_sources(folder: Path) -> dict[str, bytes]:
    """The named byte strings of cases.Sources, made in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    run = write_small_run(folder / "run.h5")
    other = folder / "other.h5"
    with h5py.File(other, "w") as f:
        f.create_dataset("x", data=np.arange(10))
    return {"run_file": run.read_bytes(), "other_hdf5": other.read_bytes()}


@pytest.fixture(scope="session")
def sources(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    return make_sources(tmp_path_factory.mktemp("sources"))


@pytest.fixture(scope="session", autouse=True)
def warm_imports() -> None:
    """Import the commands' modules once, so that the 2 s bound times the refusal, not the
    first import of numba or matplotlib in this process."""
    import importlib

    for name in ("daq.cli.figures", "daq.cli.run_input", "daq.cli.run_protocol",
                 "daq.cli.simulate", "protocols.studyfile"):  # fmt: skip
        importlib.import_module(name)
