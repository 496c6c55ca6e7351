"""Records damaged on disk: found by their checksums, and cleared to be measured again.

Each point's velocity and drive records are one HDF5 chunk with a Fletcher-32 checksum (run
files written since 2026-11-27). A chunk whose bytes changed on disk (a bad sector, a bit
flipped in a copy) fails it at every read. Before, one such point made the whole file unusable:
``biafc figures`` and ``biafc repair`` refused it, and ``--resume`` refused a file that was
complete. Now :func:`damaged_points` finds them, and :func:`clear_damaged_points` (run by
``biafc repair``) writes fresh empty records over them, marks them pending and logs which:
``run_protocol --resume`` then measures exactly those points again, on the same bench.
"""

from __future__ import annotations

from pathlib import Path

import h5py

__all__ = ["RECORDS", "bad_points", "clear_damaged_points", "damaged_points"]

#: the record datasets of a scan that carry a checksum a point
RECORDS = ("velocity", "drive")


def bad_points(ds: h5py.Dataset) -> list[tuple[int, int]]:
    """``(amplitude index, cylinder index)`` of the points of records ``ds`` ``[A, C, S]``
    that fail their checksum (empty when all read, or the dataset carries none)."""
    if not ds.fletcher32:
        return []
    try:
        ds[...]
        return []
    except OSError:
        pass
    bad = []
    for a in range(ds.shape[0]):
        for c in range(ds.shape[1]):
            try:
                ds[a, c]
            except OSError:
                bad.append((a, c))
    return bad


def damaged_points(path: str | Path) -> dict[str, list[tuple[int, int]]]:
    """Direction -> the points (0-based amplitude and cylinder indices, sorted) of run file
    ``path`` whose velocity or drive records fail their checksum; only directions with some."""
    from protocols.runfile import DIRECTIONS, open_for_reading

    out: dict[str, list[tuple[int, int]]] = {}
    with open_for_reading(path) as f:
        for direction in DIRECTIONS:
            if f"scan/{direction}" not in f:
                continue
            g = f["scan"][direction]
            bad = sorted({p for name in RECORDS if name in g for p in bad_points(g[name])})
            if bad:
                out[direction] = bad
    return out


def clear_damaged_points(path: str | Path, damaged: dict[str, list[tuple[int, int]]]) -> str:
    """Write empty records (NaN, with fresh checksums) over the ``damaged`` points of run file
    ``path``, mark them pending, log it in the file and leave a complete run ``aborted`` (so
    ``--resume`` continues it). The caller holds the file's lock and the file's open-for-write
    flags are clear. Returns the log line."""
    from protocols.runfile import RunFileWriter

    f = h5py.File(path, "r+", libver="latest")
    writer = RunFileWriter(Path(path), f)
    status = str(f.attrs.get("status", ""))
    names = []
    for direction, points in damaged.items():
        g = f["scan"][direction]
        amps, cyls = g["amplitudes"][...], g["cylinders"][...]
        units = str(g["amplitudes"].attrs.get("units", ""))
        for a, c in points:
            writer.clear_point(direction, a, c)
            names.append(f"{direction} amplitude #{a + 1} ({amps[a]:g} {units}) cylinder "
                         f"{int(cyls[c])}")  # fmt: skip
    shown = "; ".join(names[:4]) + (f"; and {len(names) - 4} more" if len(names) > 4 else "")
    line = (
        f"repaired: {len(names)} point(s) whose records failed their checksum (damaged on "
        f"disk) cleared and marked pending: {shown}; run_protocol --resume measures them again"
    )
    writer.log("error", line)
    writer.close("aborted" if status == "complete" else status)  # type: ignore[arg-type]
    return line
