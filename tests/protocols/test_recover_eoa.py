"""A writer killed after a dataset's flush and before the file's: under SWMR the chunks (and
their index) are written past the superblock's end-of-file address (EOA), which only the
file's flush writes. Clearing the killed writer's flags must also raise the EOA to the file's
size: HDF5 refused to read those bytes ("addr overflow"), and the next writer (a resume, a
repair) allocated over them, destroying measured points (a second reader)."""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np

from protocols.recover import ClearedView, clear_consistency_flags, has_consistency_flags

WRITER = """
import os, signal, sys
import h5py, numpy as np
f = h5py.File(sys.argv[1], "w", libver="latest")
v = f.create_dataset("v", shape=(8, 1000), dtype="f8", chunks=(1, 1000), fillvalue=np.nan)
done = f.create_dataset("done", shape=(8,), dtype="i1")
f.swmr_mode = True
for i in range(3):
    v[i] = np.arange(1000) + i
    v.flush()
    done[i] = 1
    f.flush()
v[3] = np.arange(1000) + 3  # a point's records flushed, the point not yet marked done
v.flush()
os.kill(os.getpid(), signal.SIGKILL)
"""


def _killed(path: Path) -> Path:
    proc = subprocess.run([sys.executable, "-c", WRITER, str(path)], timeout=60)
    assert proc.returncode != 0 and has_consistency_flags(path)
    return path


def _eoa(path: Path) -> int:
    head = path.read_bytes()[:40]
    assert head[8] >= 2 and head[9] == 8
    return int(struct.unpack_from("<Q", head, 28)[0])


def test_clearing_the_flags_raises_a_stale_end_of_file_address(tmp_path: Path) -> None:
    path = _killed(tmp_path / "k.h5")
    assert _eoa(path) < path.stat().st_size  # the window: bytes in use past the EOA
    assert clear_consistency_flags(path)
    assert _eoa(path) == path.stat().st_size and not has_consistency_flags(path)
    with h5py.File(path, "r+", libver="latest") as f:  # the next writer allocates
        f.create_dataset("more", data=np.full((4, 2000), 7.0))
        f["v"][4] = np.arange(1000) + 4
    with h5py.File(path, "r") as f:
        v = f["v"][...]
        assert f["done"][...].tolist() == [1, 1, 1, 0, 0, 0, 0, 0]
        assert np.array_equal(f["more"][...], np.full((4, 2000), 7.0))
    for i in range(5):  # every flushed record survives, the unmarked one too
        assert np.array_equal(v[i], np.arange(1000) + i), i


def test_a_read_only_view_of_the_killed_file_reads_every_flushed_record(tmp_path: Path) -> None:
    path = _killed(tmp_path / "k.h5")
    before = path.read_bytes()
    with ClearedView(path) as raw, h5py.File(raw, "r") as f:
        v = f["v"][...]
    for i in range(4):
        assert np.array_equal(v[i], np.arange(1000) + i), i
    assert path.read_bytes() == before  # reading changes nothing


def _h5clear_s(path: Path) -> None:
    """What ``h5clear -s`` (and this software before 2026-11-28) did: the flags byte zeroed
    and the checksum rewritten, the end-of-file address left as it was."""
    from protocols.recover import lookup3

    block = bytearray(path.read_bytes()[:48])
    block[11] = 0
    struct.pack_into("<I", block, 44, lookup3(bytes(block[:44])))
    with path.open("r+b") as f:
        f.write(block)


def test_a_stale_end_address_is_raised_after_the_flags_were_cleared_elsewhere(
    tmp_path: Path,
) -> None:
    """A reviewer: the address was raised only while the flags were still set, so a file whose
    flags h5clear -s (as HDF5's own message suggests) or an older repair had cleared kept its
    stale address, and a resume then wrote over the flushed records."""
    from protocols.recover import has_stale_end
    from protocols.runfile import open_for_reading

    path = _killed(tmp_path / "k.h5")
    _h5clear_s(path)
    assert not has_consistency_flags(path) and has_stale_end(path)
    with open_for_reading(path) as f:  # readers see every flushed record, changing nothing
        assert np.array_equal(f["v"][3], np.arange(1000) + 3)
    assert clear_consistency_flags(path) and not has_stale_end(path)
    with h5py.File(path, "r+", libver="latest") as f:
        f.create_dataset("more", data=np.full((4, 2000), 7.0))
    with h5py.File(path, "r") as f:
        for i in range(4):
            assert np.array_equal(f["v"][i], np.arange(1000) + i), i
