"""A cheap look at an HDF5 file's header before h5py opens it.

h5py (HDF5 2.0) opening a truncated file for SWMR reading retries its metadata reads with an
exponential back-off for minutes (the first kilobyte of a run file hung ``biafc figures`` past
150 s), and half a file opens, then fails deep inside with a ``RuntimeError``. HDF5 itself
refuses a truncated file only outside SWMR. :func:`probe_hdf5` reads the superblock (at most
a few hundred bytes) and refuses, in one line naming the file, what cannot be a whole HDF5
file: a folder, an empty file, one without the HDF5 signature, one shorter than the end-of-file
address its superblock names, one whose superblock (version 2 or later, as run files are
written) fails its checksum. A run file being written with SWMR keeps that address equal to
its size at every flush, so a live file passes; a superblock read while its writer rewrites it
is read again for :data:`TORN_GRACE_S` before it is called damaged. (Damage past the superblock
is found by HDF5 itself: :mod:`protocols.swmr_read` bounds its retry under SWMR.)
"""

from __future__ import annotations

import os
import struct
import time
from dataclasses import dataclass
from pathlib import Path

from protocols.recover import lookup3

__all__ = ["HDF5Header", "HDF5ProbeError", "probe_hdf5"]

SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: a file shorter than its stated end while a writer holds it is looked at again for this long
#: (s) before it is called truncated
LIVE_GRACE_S = 0.5
#: a superblock failing its checksum is read again for this long (s): a writer may have been
#: rewriting it (its end-of-file address changes at every flush)
TORN_GRACE_S = 0.2


class HDF5ProbeError(ValueError):
    """``path`` cannot be a whole HDF5 file; the message is one line naming it."""


@dataclass(frozen=True)
class HDF5Header:
    """What :func:`probe_hdf5` saw: ``size`` (bytes), the end-of-file address the superblock
    names (``None``: not a superblock layout read here) and its consistency ``flags`` (non-zero
    while a writer holds the file, or after one was killed)."""

    size: int
    end: int | None
    flags: int


def _signature_offset(f: object, size: int) -> int | None:
    """Where the superblock starts: 0, 512, 1024, 2048, ... (after a user block)."""
    offset = 0
    while offset + len(SIGNATURE) <= size:
        f.seek(offset)  # type: ignore[attr-defined]
        if f.read(len(SIGNATURE)) == SIGNATURE:  # type: ignore[attr-defined]
            return offset
        offset = 512 if offset == 0 else offset * 2
    return None


def _stated_end(head: bytes) -> tuple[int, int] | None:
    """``(end-of-file address, consistency flags)`` of the superblock at the start of ``head``
    (HDF5 file format, superblock versions 0 to 3), or None when it cannot be read."""
    if len(head) < 12:
        return None
    version = head[8]
    if version in (0, 1):
        if len(head) < 16:
            return None
        size_offsets = head[13]
        flags = struct.unpack_from("<I", head, 20)[0] if len(head) >= 24 else 0
        base_at = 24 if version == 0 else 28
    elif version in (2, 3):
        size_offsets = head[9]
        flags = head[11]
        base_at = 12
    else:
        return None
    if size_offsets not in (2, 4, 8):
        return None
    fmt = {2: "<H", 4: "<I", 8: "<Q"}[size_offsets]
    eof_at = base_at + 2 * size_offsets
    if len(head) < eof_at + size_offsets:
        return None
    (end,) = struct.unpack_from(fmt, head, eof_at)
    if end == (1 << (8 * size_offsets)) - 1:  # the undefined address
        return None
    return int(end), int(flags)


def _checksum_fails(head: bytes) -> tuple[int, int] | None:
    """``(first, last byte)`` of a version 2+ superblock at the start of ``head`` whose stored
    checksum (lookup3 of the bytes before it) does not match; ``None`` when it matches or the
    superblock has no checksum (versions 0 and 1) or cannot be read."""
    if len(head) < 12 or head[8] < 2 or head[9] not in (2, 4, 8):
        return None
    n = 12 + 4 * head[9]
    if len(head) < n + 4:
        return None
    if lookup3(head[:n]) == struct.unpack_from("<I", head, n)[0]:
        return None
    return 0, n + 3


def _look(p: Path) -> tuple[int, int | None, int, tuple[int, int] | None]:
    """``(size, stated end or None, flags, bytes of a superblock failing its checksum)``."""
    with p.open("rb") as f:
        size = os.fstat(f.fileno()).st_size
        if size == 0:
            return 0, None, 0, None
        offset = _signature_offset(f, size)
        if offset is None:
            raise HDF5ProbeError(
                f"{p}: not an HDF5 file (no HDF5 signature in its {size} bytes); give a run "
                "file written by run_protocol or biafc simulate"
            )
        f.seek(offset)
        head = f.read(96)
    bad = _checksum_fails(head)
    if bad is not None:
        return size, None, 0, (bad[0] + offset, bad[1] + offset)
    stated = _stated_end(head)
    if stated is None:
        return size, None, 0, None
    return size, stated[0] + offset, stated[1], None


def probe_hdf5(path: str | Path) -> HDF5Header:
    """Refuse (:class:`HDF5ProbeError`, one line) a path that is no whole HDF5 file: a folder,
    missing, empty, without the signature, or shorter than its superblock says. Reads at most
    a few hundred bytes; a file whose writer is live gets :data:`LIVE_GRACE_S` to catch up."""
    p = Path(path)
    if p.is_dir():
        raise HDF5ProbeError(f"{p} is a folder; give a run file (.h5)")
    if not p.exists():
        raise HDF5ProbeError(f"{p} does not exist")
    try:
        t0 = time.monotonic()
        size, end, flags, bad = _look(p)
        while (bad is not None and time.monotonic() < t0 + TORN_GRACE_S) or (
            end is not None and size < end and flags and time.monotonic() < t0 + LIVE_GRACE_S
        ):
            time.sleep(0.02)
            size, end, flags, bad = _look(p)
    except OSError as exc:
        raise HDF5ProbeError(f"{p}: cannot read ({exc.strerror or exc})") from None
    if size == 0:
        raise HDF5ProbeError(f"{p}: an empty file (0 bytes), not a run file")
    if bad is not None:
        raise HDF5ProbeError(
            f"{p}: damaged: its HDF5 superblock (bytes {bad[0]}-{bad[1]}) fails its checksum, "
            "so where its objects lie is unknown; use an undamaged copy"
        )
    if end is not None and size < end:
        raise HDF5ProbeError(
            f"{p}: truncated: {size} of the {end} bytes its HDF5 header names (an incomplete "
            "copy or download?); copy the whole file again"
        )
    return HDF5Header(size, end, flags)
