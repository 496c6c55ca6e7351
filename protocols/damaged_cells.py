"""A study output's results damaged on disk: found by their checksums, and cleared to be run
again.

A study output's per-cell status, metrics and spectra are chunked (4,096 cells a chunk; 64 for
the spectra), each chunk with a Fletcher-32 checksum (:mod:`protocols.studyfile`). A chunk whose
bytes changed on disk fails it at every read, and the whole output was refused, by
``biafc figures``, by ``biafc repair`` and by the study run again: hours of computing lost to a
bad sector. :func:`damaged_chunks` finds them, and :func:`clear_damaged_cells` (run by
``biafc repair``) writes an empty chunk in place of each (status 0, results NaN) and marks those
cells not run: the same ``biafc study`` command then computes exactly them again.

An empty chunk is written as it is stored, without its checksum (``write_direct_chunk`` with
the filter marked skipped): a chunk at the end of a dataset is only partly inside it, and HDF5
reads such a chunk before writing into it, which the damaged one refuses. The checksum is back
as soon as the study writes those cells again.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

__all__ = ["clear_damaged_cells", "damaged_cells", "damaged_chunks", "shown"]

#: Fletcher-32 is the one filter of these datasets: bit 0 set = the filter was not applied
_CHECKSUM_SKIPPED = 0x1


def _checked(f: h5py.File) -> list[h5py.Dataset]:
    """The datasets of study output ``f`` that carry a checksum a chunk."""
    out = [f["cells/status"]] if "cells/status" in f else []
    for group in ("metrics", "spectra"):
        if group in f:
            out += [ds for ds in f[group].values() if isinstance(ds, h5py.Dataset)]
    return [ds for ds in out if ds.fletcher32 and ds.chunks is not None]


def damaged_chunks(f: h5py.File) -> list[tuple[str, int, int]]:
    """``(dataset name, first cell, end cell)`` of every chunk of study output ``f`` that fails
    its checksum."""
    out = []
    for ds in _checked(f):
        try:
            ds[...]
            continue
        except OSError:
            pass
        step = ds.chunks[0]
        for start in range(0, ds.shape[0], step):
            stop = min(start + step, ds.shape[0])
            try:
                ds[start:stop]
            except OSError:
                out.append((ds.name, start, stop))
    return out


def damaged_cells(path: str | Path) -> list[tuple[int, int]]:
    """The cell ranges ``[start, end)`` of study output ``path`` whose results fail their
    checksum, merged and sorted (empty when none)."""
    from protocols.runfile import open_for_reading

    with open_for_reading(path) as f:
        return _merged(damaged_chunks(f))


def _merged(chunks: list[tuple[str, int, int]]) -> list[tuple[int, int]]:
    out: list[tuple[int, int]] = []
    for start, stop in sorted((a, b) for _, a, b in chunks):
        if out and start <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], stop))
        else:
            out.append((start, stop))
    return out


def shown(ranges: list[tuple[int, int]]) -> str:
    """``"cells 1-4096, 8193-9000"`` (1-based, as the progress display counts them)."""
    return "cells " + ", ".join(f"{a + 1}-{b}" if b - a > 1 else f"{a + 1}" for a, b in ranges)


def clear_damaged_cells(path: str | Path) -> str | None:
    """Replace every damaged chunk of study output ``path`` by an empty one, mark its cells not
    run, and mark a complete study ``incomplete``. The caller holds the file's lock and its
    open-for-write flags are clear. Returns what was done (one line), or ``None`` when nothing
    was damaged."""
    with h5py.File(path, "r") as f:
        chunks = damaged_chunks(f)
    if not chunks:
        return None
    ranges = _merged(chunks)
    with h5py.File(path, "r+", libver="latest") as f:
        for name, start, _ in chunks:
            ds = f[name]
            fill = 0 if name.endswith("status") else np.nan
            empty = np.full(ds.chunks, fill, dtype=ds.dtype)
            offset = (start,) + (0,) * (ds.ndim - 1)
            ds.id.write_direct_chunk(offset, empty.tobytes(), filter_mask=_CHECKSUM_SKIPPED)
        status = f["cells/status"]
        for start, stop in ranges:
            status[start:stop] = 0
        if f.attrs.get("status") == "complete":
            f.attrs["status"] = "incomplete"
        f.flush()
    n = sum(b - a for a, b in ranges)
    return (
        f"{n} cell(s) whose results failed their checksum (damaged on disk) cleared and marked "
        f"not run ({shown(ranges)}); run the study again to compute them"
    )
