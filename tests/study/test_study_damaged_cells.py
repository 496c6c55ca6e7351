"""A study output whose results are damaged on disk (:mod:`protocols.damaged_cells`). Before,
the whole output was refused by ``biafc figures``, ``biafc repair`` and the study run again;
now ``biafc repair`` clears the damaged chunks' cells and the same command computes them
again."""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.cli.biafc import main
from protocols.damaged_cells import clear_damaged_cells, damaged_cells
from protocols.studyfile import read_study
from tests.engine.helpers import flip_bytes


def _damage(path: Path, name: str, chunk: int) -> None:
    with h5py.File(path, "r") as f:
        info = f[name].id.get_chunk_info(chunk)
    flip_bytes(path, info.byte_offset + 8)


def test_repair_clears_the_damaged_cells_and_the_study_computes_them_again(
    serial_reference: Path, tiny_study: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "s.h5"
    shutil.copy(serial_reference, out)
    _damage(out, "metrics/asymmetry_ratio", 0)
    assert main(["figures", str(out), "--out", str(tmp_path / "figs")]) == 2
    err = capsys.readouterr().err.strip()
    assert "the results of 12 cell(s) fail their checksum" in err and "cells 1-12" in err
    assert f"biafc repair {out} clears them" in err
    assert main(["repair", str(out)]) == 0
    said = capsys.readouterr().out
    assert "12 cell(s) whose results failed their checksum" in said and "incomplete" in said
    cleared = read_study(out)
    assert cleared.attrs["status"] == "incomplete" and np.all(cleared.status == 0)
    assert main(["study", str(tiny_study), "--workers", "0", "--out", str(out), "-q"]) == 0
    a, b = read_study(out), read_study(serial_reference)
    assert a.attrs["status"] == "complete" and np.array_equal(a.status, b.status)
    for name, values in b.metrics.items():
        np.testing.assert_array_equal(a.metrics[name], values)
    with h5py.File(out, "r") as f:  # the checksum is back with the results
        assert f["metrics/asymmetry_ratio"].id.get_chunk_info(0).filter_mask == 0


def _synthetic(path: Path) -> None:
    """A study output's checked datasets, 10 cells in chunks of 4: [0, 4), [4, 8), [8, 10)."""
    with h5py.File(path, "w", libver="latest") as f:
        f.attrs["status"] = "complete"
        kw = {"chunks": (4,), "fletcher32": True}
        f.create_dataset("cells/status", data=np.ones(10, "i1"), **kw)
        f.create_dataset("metrics/a", data=np.arange(10.0), **kw)
        f.create_dataset("metrics/b", data=np.arange(10.0) * 2, **kw)
        f.create_dataset("spectra/ltr", data=np.ones((10, 3), "f4"), chunks=(4, 3),
                         fletcher32=True)  # fmt: skip


def test_a_damaged_chunk_at_the_end_of_a_dataset_is_cleared_too(tmp_path: Path) -> None:
    """The last chunk lies partly outside its dataset, and HDF5 reads such a chunk before it
    writes into it: a plain write of the cleared cells failed on the damaged checksum."""
    path = tmp_path / "s.h5"
    _synthetic(path)
    _damage(path, "metrics/b", 2)  # cells 9-10, the partial chunk
    _damage(path, "spectra/ltr", 1)  # cells 5-8
    assert damaged_cells(path) == [(4, 10)]
    line = clear_damaged_cells(path)
    assert line is not None and "6 cell(s)" in line and "cells 5-10" in line
    with h5py.File(path, "r") as f:
        assert list(f["cells/status"][...]) == [1, 1, 1, 1, 0, 0, 0, 0, 0, 0]
        assert np.array_equal(f["metrics/a"][...], np.arange(10.0))  # intact
        b = f["metrics/b"][...]
        assert np.array_equal(b[:8], np.arange(8.0) * 2) and np.isnan(b[8:]).all()
        assert np.isnan(f["spectra/ltr"][4:8]).all() and (f["spectra/ltr"][:4] == 1).all()
        assert f.attrs["status"] == "incomplete"
    assert damaged_cells(path) == [] and clear_damaged_cells(path) is None


def test_a_repair_that_fails_on_the_way_says_so_in_one_line(
    serial_reference: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:  # fmt: skip
    """A second reader: damage that the clearing did not remove (or HDF5 refusing the clearing's
    write) ended ``biafc repair`` in a traceback of DamagedCellsError or OSError."""
    import protocols.damaged_cells

    out = tmp_path / "s.h5"
    shutil.copy(serial_reference, out)
    _damage(out, "metrics/asymmetry_ratio", 0)

    def cannot_write(path: Path) -> str | None:
        raise OSError("Can't write unprocessed chunk data (addr overflow)")

    monkeypatch.setattr(protocols.damaged_cells, "clear_damaged_cells", cannot_write)
    assert main(["repair", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"biafc repair: failed: {out}: OSError: "), err
    monkeypatch.setattr(protocols.damaged_cells, "clear_damaged_cells", lambda path: None)
    assert main(["repair", str(out)]) == 1  # cleared nothing: the damage remains
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "DamagedCellsError" in err[0] and "checksum" in err[0], err
