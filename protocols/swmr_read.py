"""Open an HDF5 file for SWMR reading with a bounded metadata retry.

A SWMR reader retries a metadata read that fails its checksum (a writer may be flushing that
very block), sleeping 1 ns, 2 ns, 4 ns, ... between tries, for HDF5's default 100 tries: on a
file that is damaged rather than being flushed (a killed writer's file with bytes overwritten)
that back-off never ends in practice (2^100 ns). Measured here (HDF5 2.0.0, h5py 3.16) on a
killed run file with 500 bytes of its metadata zeroed: 0.003 s to the checksum error at 1 try,
0.049 s at 25, 0.29 s at 28, 1.1 s at 30 (the sleeps sum to about 2^tries ns); unbounded
(> 15 s, killed) at the default.

h5py does not expose ``H5Pset_metadata_read_attempts``, so :func:`open_swmr` calls it through
:mod:`ctypes` on the HDF5 library h5py itself loaded (the same library, so the file-access
property list's id is valid in it), with :data:`METADATA_READ_ATTEMPTS` tries: a live writer's
flush has 0.27 s to finish, and a damaged file is refused within that. Where that library
cannot be found or the call fails (:func:`retry_bound_available` is False), the file opens
with HDF5's default (unbounded) retry, as h5py's own ``swmr=True`` does.
"""

from __future__ import annotations

import ctypes
import sys
from functools import cache
from pathlib import Path
from typing import Any

import h5py

try:  # h5py's lock around every HDF5 call (the library is not built thread-safe)
    from h5py._objects import phil as _hdf5_lock
except ImportError:  # pragma: no cover - an h5py without it
    import threading

    _hdf5_lock = threading.RLock()

__all__ = ["METADATA_READ_ATTEMPTS", "open_swmr", "retry_bound_available"]

#: tries of a metadata read that fails its checksum: the back-off sleeps sum to about
#: 2^28 ns = 0.27 s before the read fails
METADATA_READ_ATTEMPTS = 28


def _loaded_hdf5_paths() -> list[str]:
    """Paths of the HDF5 library this process has loaded (Linux: ``/proc/self/maps``), then
    the copies a binary h5py wheel ships next to it (macOS, Windows, or no ``/proc``)."""
    paths: list[str] = []
    try:
        with open("/proc/self/maps") as maps:
            for line in maps:
                name = line.rsplit("/", 1)[-1].strip()
                if name.startswith(("libhdf5-", "libhdf5.")) and "/" in line:
                    path = line[line.index("/") :].strip()
                    if path not in paths:
                        paths.append(path)
    except OSError:
        pass
    pkg = Path(h5py.__file__).parent
    for folder, pattern in (
        (pkg.parent / "h5py.libs", "libhdf5[-.]*"),
        (pkg / ".dylibs", "libhdf5[-.]*"),
        (pkg, "hdf5*.dll"),
    ):
        for p in sorted(folder.glob(pattern)) if folder.is_dir() else ():
            if "_hl" not in p.name and str(p) not in paths:
                paths.append(str(p))
    return paths


def _set_attempts() -> Any:
    """``H5Pset_metadata_read_attempts`` of the HDF5 library h5py uses, or ``None``."""
    with _hdf5_lock:  # no other thread in HDF5 meanwhile (ctypes releases the GIL)
        return _find_set_attempts()


@cache
def _find_set_attempts() -> Any:
    h5py.h5p.create(h5py.h5p.FILE_ACCESS)  # the library is loaded and initialised
    want = h5py.version.hdf5_version_tuple[:3]
    for path in _loaded_hdf5_paths():
        try:
            lib = ctypes.CDLL(path)
            fn = lib.H5Pset_metadata_read_attempts
            get = lib.H5Pget_metadata_read_attempts
            version = lib.H5get_libversion
        except (OSError, AttributeError):
            continue
        major, minor, release = ctypes.c_uint(), ctypes.c_uint(), ctypes.c_uint()
        version.argtypes = [ctypes.POINTER(ctypes.c_uint)] * 3
        if version(ctypes.byref(major), ctypes.byref(minor), ctypes.byref(release)) < 0:
            continue
        if (major.value, minor.value, release.value) != want:
            continue  # another HDF5 than h5py's: its ids mean nothing there
        fn.argtypes = [ctypes.c_int64, ctypes.c_uint]
        get.argtypes = [ctypes.c_int64, ctypes.POINTER(ctypes.c_uint)]
        probe = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
        got = ctypes.c_uint()
        if fn(probe.id, 7) < 0 or get(probe.id, ctypes.byref(got)) < 0 or got.value != 7:
            continue  # not the library that made the id (a second copy)
        return fn
    return None


def retry_bound_available() -> bool:
    """Whether :func:`open_swmr` bounds the retry (h5py's HDF5 library was found)."""
    return _set_attempts() is not None


def _file_access() -> Any:
    """A file-access property list as h5py makes one for ``h5py.File(..., "r")``."""
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    fapl.set_libver_bounds(h5py.h5f.LIBVER_EARLIEST, h5py.h5f.LIBVER_LATEST)
    return fapl


def open_swmr(path: str | Path) -> h5py.File:
    """``h5py.File(path, "r", swmr=True)`` with :data:`METADATA_READ_ATTEMPTS` tries of a
    metadata read that fails its checksum (see the module); raises as h5py does."""
    fapl = _file_access()
    fn = _set_attempts()
    if fn is not None:
        with _hdf5_lock:
            failed = fn(fapl.id, METADATA_READ_ATTEMPTS) < 0
        if failed:
            fapl = _file_access()  # left as h5py makes it
    name = str(path).encode(sys.getfilesystemencoding(), "surrogateescape")
    fid = h5py.h5f.open(name, h5py.h5f.ACC_RDONLY | h5py.h5f.ACC_SWMR_READ, fapl=fapl)
    return h5py.File(fid)
