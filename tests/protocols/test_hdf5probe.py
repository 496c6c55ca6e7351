"""A run file's header looked at before h5py opens it (issue 16): a truncated, empty, foreign
or damaged file is refused in one line at once (h5py's SWMR reader retried a truncated file for
minutes); a file being written still reads, point by point."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

from protocols.hdf5probe import HDF5ProbeError, probe_hdf5
from protocols.runfile import RunFileError, RunFileWriter, ScanSpec, read_run
from tests.engine.helpers import chain_info


def _writer(path: Path) -> RunFileWriter:
    t = np.arange(2000) / 200e3
    spec = ScanSpec("ltr", np.array([1e-6, 2e-6]), "m", np.arange(1, 6, dtype=np.int32), t,
                    8920.0, cycles=21.0, drive_units="m")  # fmt: skip
    return RunFileWriter.create(path, backend="sim", chain=chain_info(), scans=[spec])


def test_a_file_being_written_reads_at_every_point(tmp_path: Path) -> None:
    path = tmp_path / "live.h5"
    w = _writer(path)
    try:
        for c in range(5):
            w.write_point("ltr", 0, c, np.ones(2000), np.ones(2000))
            header = probe_hdf5(path)
            assert header.flags != 0 and header.end == header.size
            assert int(read_run(path).scans["ltr"].is_done().sum()) == c + 1
    finally:
        w.close("complete")
    assert probe_hdf5(path).flags == 0


@pytest.mark.parametrize("keep", [1024, 0.5])
def test_a_truncated_copy_is_refused_at_once(tmp_path: Path, keep: float) -> None:
    full = tmp_path / "full.h5"
    _writer(full).close("complete")
    data = full.read_bytes()
    cut = tmp_path / "cut.h5"
    n = int(keep if keep > 1 else len(data) * keep)
    cut.write_bytes(data[:n])
    t0 = time.perf_counter()
    with pytest.raises(RunFileError, match=rf"cut\.h5: truncated: {n} of the {len(data)} bytes"):
        read_run(cut)
    assert time.perf_counter() - t0 < 1.0


def test_a_truncated_copy_of_a_file_being_written_is_refused_after_the_grace(
    tmp_path: Path,
) -> None:
    live = tmp_path / "live.h5"
    w = _writer(live)
    try:
        cut = tmp_path / "cut.h5"
        cut.write_bytes(live.read_bytes()[:1024])  # flags set: a writer seemed to hold it
        t0 = time.perf_counter()
        with pytest.raises(RunFileError, match="truncated"):
            read_run(cut)
        assert time.perf_counter() - t0 < 2.0
    finally:
        w.close("complete")


def test_damaged_metadata_is_refused_at_once(tmp_path: Path) -> None:
    path = tmp_path / "run.h5"
    _writer(path).close("complete")
    data = bytearray(path.read_bytes())
    data[100:600] = b"\xaa" * 500
    path.write_bytes(bytes(data))
    t0 = time.perf_counter()
    with pytest.raises(RunFileError, match=r"run\.h5: damaged HDF5 file"):
        read_run(path)
    assert time.perf_counter() - t0 < 1.0


def test_a_superblock_failing_its_checksum_is_refused_and_a_torn_read_is_read_again(
    tmp_path: Path,
) -> None:
    path = tmp_path / "run.h5"
    _writer(path).close("complete")
    good = path.read_bytes()
    bad = bytearray(good)
    bad[28:32] = b"\0\0\0\0"  # the end-of-file address of the version 3 superblock
    path.write_bytes(bytes(bad))
    with pytest.raises(
        HDF5ProbeError, match=r"run\.h5: damaged: its HDF5 superblock \(bytes 0-47\)"
    ):
        probe_hdf5(path)
    # read while its writer rewrites it: right again within the grace, so it passes
    fixer = threading.Timer(0.05, lambda: path.write_bytes(good))
    fixer.start()
    try:
        assert probe_hdf5(path).end == len(good)
    finally:
        fixer.join()


@pytest.mark.parametrize(
    ("content", "message"),
    [(b"", "an empty file"), (b"hello\n", "not an HDF5 file"), (None, "is a folder")],
)
def test_what_is_no_hdf5_file(tmp_path: Path, content: bytes | None, message: str) -> None:
    path = tmp_path / "x.h5"
    if content is None:
        path.mkdir()
    else:
        path.write_bytes(content)
    with pytest.raises(HDF5ProbeError, match=message):
        probe_hdf5(path)
