"""Open a run file whose writer was killed: HDF5's SWMR-write consistency flags.

A process killed while writing with SWMR leaves the superblock's "file consistency flags" set,
and HDF5 then refuses to open the file for writing ("may use h5clear"). The data is intact
(every point was flushed). :func:`clear_consistency_flags` does what ``h5clear -s
--increment=0`` does: it zeroes the flags byte of a version 2+ superblock, raises the
superblock's end-of-file address (EOA) to the file's size where it lies below, and rewrites
the superblock checksum (Bob Jenkins' lookup3, as HDF5 computes it).

The EOA matters: under SWMR a dataset's flush writes its chunks and their index at the end of
the file, but only a flush of the whole file writes the superblock's EOA. A writer killed
between the two (a point's records flushed, the point not yet marked done) leaves bytes in use
beyond the EOA: HDF5 refuses to read them ("addr overflow"), and the next writer (a resume, a
repair) allocates over them, destroying measured points (a second reader; before,
``--resume`` or ``biafc repair`` of such a file lost every point). :class:`ClearedView` lets
a reader see the file as if cleared without writing a byte (``biafc figures`` on a killed
file).
"""

from __future__ import annotations

import io
import os
import struct
from pathlib import Path
from typing import Any

__all__ = [
    "ClearedView",
    "clear_consistency_flags",
    "has_consistency_flags",
    "has_stale_end",
    "lookup3",
]

_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_M = 0xFFFFFFFF


def _rot(x: int, k: int) -> int:
    return ((x << k) | (x >> (32 - k))) & _M


def lookup3(data: bytes, initval: int = 0) -> int:
    """Jenkins' ``hashlittle`` (lookup3) of ``data``: HDF5's metadata checksum."""
    length = len(data)
    a = b = c = (0xDEADBEEF + length + initval) & _M
    i = 0
    while length > 12:
        x, y, z = struct.unpack_from("<III", data, i)
        a, b, c = (a + x) & _M, (b + y) & _M, (c + z) & _M
        a = (a - c) & _M
        a ^= _rot(c, 4)
        c = (c + b) & _M
        b = (b - a) & _M
        b ^= _rot(a, 6)
        a = (a + c) & _M
        c = (c - b) & _M
        c ^= _rot(b, 8)
        b = (b + a) & _M
        a = (a - c) & _M
        a ^= _rot(c, 16)
        c = (c + b) & _M
        b = (b - a) & _M
        b ^= _rot(a, 19)
        a = (a + c) & _M
        c = (c - b) & _M
        c ^= _rot(b, 4)
        b = (b + a) & _M
        length -= 12
        i += 12
    if length == 0:
        return c
    x, y, z = struct.unpack("<III", data[i:].ljust(12, b"\0"))
    a, b, c = (a + x) & _M, (b + y) & _M, (c + z) & _M
    c ^= b
    c = (c - _rot(b, 14)) & _M
    a ^= c
    a = (a - _rot(c, 11)) & _M
    b ^= a
    b = (b - _rot(a, 25)) & _M
    c ^= b
    c = (c - _rot(b, 16)) & _M
    a ^= c
    a = (a - _rot(c, 4)) & _M
    b ^= a
    b = (b - _rot(a, 14)) & _M
    c ^= b
    c = (c - _rot(b, 24)) & _M
    return c


def clear_consistency_flags(path: str | Path) -> bool:
    """Clear the SWMR-write flags of ``path`` and raise a stale end-of-file address to the
    file's size; True when something was changed. The address is raised whether or not the
    flags are still set: ``h5clear -s`` (which HDF5's own error message suggests) and this
    software before 2026-11-28 cleared the flags and left it stale.

    Only a superblock of version 2 or later at offset 0 is handled (what ``libver="latest"``
    writes); anything else is left alone (returns False).
    """
    p = Path(path)
    with p.open("r+b") as f:
        head = f.read(64)
        block = _cleared_superblock(head, os.fstat(f.fileno()).st_size)
        if block is None:
            return False
        f.seek(0)
        f.write(block)
    return True


def _layout(head: bytes) -> tuple[int, str] | None:
    """``(checksum offset, struct format of an address)`` of a version 2+ superblock at the
    start of ``head`` whose checksum holds, or None (not a layout we know: never written)."""
    if len(head) < 12 or head[:8] != _SIGNATURE or head[8] < 2 or head[9] not in (2, 4, 8):
        return None
    n = 12 + 4 * head[9]
    if len(head) < n + 4:
        return None
    (stored,) = struct.unpack_from("<I", head, n)
    if lookup3(bytes(head[:n])) != stored:
        return None
    return n, {2: "<H", 4: "<I", 8: "<Q"}[head[9]]


def _end_address(head: bytes, fmt: str) -> int:
    """The superblock's end-of-file address (fields: base address, superblock extension
    address, end-of-file address, root group address, each ``fmt``)."""
    return int(struct.unpack_from(fmt, head, 12 + 2 * struct.calcsize(fmt))[0])


def _cleared_superblock(head: bytes, file_size: int) -> bytes | None:
    """The superblock at the start of ``head`` with its consistency flags cleared, its EOA at
    least ``file_size`` (bytes) and its checksum rewritten, or ``None`` when there is nothing
    to change (or not a layout we know: then nothing is ever written into it). Only a
    superblock at offset 0 is read here, so its base address is 0 and the EOA compares with
    the file's size as it is. An EOA above the size (a file cut short) is left: that file is
    not whole (:mod:`protocols.hdf5probe` refuses it)."""
    layout = _layout(head)
    if layout is None:
        return None
    n, fmt = layout
    block = bytearray(head[: n + 4])
    stale = _end_address(head, fmt) < file_size  # bytes a killed writer flushed past it
    if block[11] == 0 and not stale:
        return None
    block[11] = 0
    if stale:
        struct.pack_into(fmt, block, 12 + 2 * struct.calcsize(fmt), file_size)
    struct.pack_into("<I", block, n, lookup3(bytes(block[:n])))
    return bytes(block)


def has_consistency_flags(path: str | Path) -> bool:
    """Whether ``path`` carries the "open for write" flags of a writer that never closed it."""
    with Path(path).open("rb") as f:
        head = f.read(64)
    return _layout(head) is not None and head[11] != 0


def has_stale_end(path: str | Path) -> bool:
    """Whether ``path``'s superblock names an end-of-file address below the file's size: bytes
    a killed writer flushed past it, which HDF5 refuses to read and a writer would allocate
    over (:func:`clear_consistency_flags` raises it)."""
    with Path(path).open("rb") as f:
        head = f.read(64)
        size = os.fstat(f.fileno()).st_size
    layout = _layout(head)
    return layout is not None and _end_address(head, layout[1]) < size


class ClearedView(io.RawIOBase):
    """A read-only view of an HDF5 file as if :func:`clear_consistency_flags` had run: the
    superblock's consistency flags read as cleared and its end-of-file address as at least
    the file's size, every other byte as on disk. The file itself is never
    written, so a reader (``biafc figures``) opens a killed run file without changing it::

        with ClearedView(path) as raw, h5py.File(raw, "r") as f: ...
    """

    def __init__(self, path: str | Path) -> None:
        super().__init__()
        self._f = Path(path).open("rb")
        head = self._f.read(64)
        self._patch = _cleared_superblock(head, os.fstat(self._f.fileno()).st_size) or b""
        self._f.seek(0)

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._f.seek(offset, whence)

    def tell(self) -> int:
        return self._f.tell()

    def readinto(self, b: Any) -> int:
        pos = self._f.tell()
        n = self._f.readinto(b)
        if n and pos < len(self._patch):
            end = min(len(self._patch), pos + n)
            memoryview(b)[: end - pos] = self._patch[pos:end]
        return n or 0

    def close(self) -> None:
        self._f.close()
        super().close()
