"""Where the compiled DEM kernel lives, and a notice while it compiles.

numba compiles the kernel (:mod:`sim_backend.dem.kernel`) on first use, 6-10 s, and keeps the
machine code on disk. By default numba writes it next to the sources (inside the checkout of an
editable install, in a possibly read-only site-packages otherwise); here it goes to the user's
cache folder, ``<cache_dir>/numba`` (:func:`instruments.user_cache.cache_dir`: platformdirs'
user cache folder of biafc-lab, or ``$BIAFC_CACHE_DIR``), for the project's own files only.
``$NUMBA_CACHE_DIR`` or ``$NUMBA_CACHE_LOCATOR_CLASSES``, when set, win; a cache folder that
cannot be written falls back to numba's own choice. numba picks a function's cache folder when it
decorates it, so every module with a cached function calls :func:`install_cache_locator` before
its decorators (``tests/dem/test_kernel_cache.py`` checks them all).

While the first call of a process compiles (or loads) the kernel, :func:`compile_notice` tells
the reporter set by :func:`set_compile_reporter` (the command-line tools print one line, and the
elapsed time on a terminal): ``("start" | "tick" | "done", elapsed_s, cache_folder, cold)``.
``biafc warmup`` compiles it ahead of time.

numba names a compiled function's files by its first line (``kernel.run_chunks-396.py311.nbi`` and
``.1.nbc``), so an update that moves a function leaves its old files behind, about 0.9 MB for the
kernel each time. :func:`remove_stale_compiled` deletes them, once per process, after the kernel's
first run.
"""

from __future__ import annotations

import functools
import os
import re
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from instruments.beside import beside

__all__ = [
    "CompileReporter",
    "announce_if_cold",
    "cache_note",
    "compile_notice",
    "expected_cache_folder",
    "install_cache_locator",
    "kernel_cache_dir",
    "kernel_cache_in_use",
    "kernel_cached_on_disk",
    "kernel_loaded",
    "remove_stale_compiled",
    "set_compile_reporter",
    "stale_compiled_files",
]

#: (phase "start" | "tick" | "done", elapsed s, cache folder, cold: nothing on disk yet)
CompileReporter = Callable[[str, float, Path, bool], None]

_PACKAGES = ("sim_backend", "benchmarks", "analysis", "daq", "instruments", "protocols", "tests")
_ROOT = Path(__file__).resolve().parents[2]
_REPORTER: CompileReporter | None = None
_INSTALLED = False
_ANNOUNCED = False
_SWEPT = False
#: numba's name of a cached function's index (``kind`` nbi) or data file (``1.nbc``)
_CACHED_FILE = re.compile(r"(?P<stem>.+)-(?P<line>\d+)\.(?P<tag>py\d+)\.(?P<kind>nbi|\d+\.nbc)")


def kernel_cache_dir() -> Path:
    """The folder of the compiled kernel: ``<cache_dir>/numba``."""
    from instruments.user_cache import cache_dir

    return cache_dir() / "numba"


def kernel_cache_in_use() -> Path:
    """The folder numba really keeps the kernel in (imports the kernel, compiles nothing): under
    :func:`kernel_cache_dir`, or ``$NUMBA_CACHE_DIR``, or, where the cache folder cannot be
    written, numba's own choice beside the sources."""
    from sim_backend.dem.kernel import run_chunks

    path = getattr(getattr(run_chunks, "_cache", None), "_cache_path", None)
    return Path(path) if path else kernel_cache_dir()


def cache_note() -> str:
    """Where the kernel is cached, for a person: the folder, and why when it is not the user's
    cache folder (``biafc warmup`` said the cache folder while numba wrote beside the sources)."""
    in_use, wanted = kernel_cache_in_use(), kernel_cache_dir()
    if in_use == wanted or wanted in in_use.parents:
        return f"cache {wanted}"
    if os.environ.get("NUMBA_CACHE_DIR"):
        return f"cache {in_use} ($NUMBA_CACHE_DIR)"
    return (
        f"cache {in_use}: the cache folder {wanted} cannot be written, so numba keeps it beside "
        "the sources (set $BIAFC_CACHE_DIR to a folder you can write)"
    )


def _ours(py_file: str) -> bool:
    try:
        rel = Path(py_file).resolve().relative_to(_ROOT)
    except (ValueError, OSError):
        return False
    return bool(rel.parts) and rel.parts[0] in _PACKAGES


def install_cache_locator() -> None:
    """Put the project's numba cache in :func:`kernel_cache_dir` (call before any
    ``@njit(cache=True)`` of the project runs; idempotent)."""
    global _INSTALLED
    if _INSTALLED:
        return
    _INSTALLED = True
    if os.environ.get("NUMBA_CACHE_DIR") or os.environ.get("NUMBA_CACHE_LOCATOR_CLASSES"):
        return
    from numba.core import caching

    base: Any = getattr(caching, "UserProvidedCacheLocator", None) or getattr(
        caching, "_UserProvidedCacheLocator", None
    )
    impl: Any = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    if base is None or impl is None:  # a numba without these internals: its default
        return
    mixin = base.__mro__[1]  # the source-file-backed locator: checks and creates the folder

    class BiafcCacheLocator(base):  # type: ignore[misc, valid-type]
        """The project's files: cache in the user's cache folder."""

        def __init__(self, py_func: Any, py_file: str) -> None:
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            sub = self.get_suitable_cache_subpath(py_file)
            self._cache_path = str(kernel_cache_dir() / sub)

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> Any:
            if not _ours(py_file):
                return None
            return mixin.from_function.__func__(cls, py_func, py_file)

    impl._locator_classes.insert(0, BiafcCacheLocator)


def _can_write(folder: Path) -> bool:
    """Whether ``folder`` is, or can be made, a folder this process writes (its nearest existing
    ancestor a writable folder); no file is created."""
    here = folder
    while not here.exists():
        if here.parent == here:
            return False
        here = here.parent
    return here.is_dir() and os.access(here, os.W_OK | os.X_OK)


def expected_cache_folder() -> Path:
    """Where numba will keep the kernel, without importing it: ``$NUMBA_CACHE_DIR`` when set,
    :func:`kernel_cache_dir` when it can be written, else numba's own choice beside the
    sources (``sim_backend/dem/__pycache__``)."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:
        return Path(env)
    wanted = kernel_cache_dir()
    beside = Path(__file__).resolve().parent / "__pycache__"
    if _can_write(wanted) or not _can_write(beside):  # neither: numba's user-wide folder,
        return wanted  # not guessed here (the notice may then say a compile once too often)
    return beside


def kernel_index_folder() -> Path:
    """The folder numba keeps this installation's kernel index in: beside the sources as they
    are, or, in a cache folder (:func:`expected_cache_folder`), numba's subfolder for the
    source folder (its name and the sha1 of its absolute path). The user's cache folder holds
    one per installation: before, an index of another clone's counted as this one's (a fresh
    clone estimated 00:00, then compiled for 9.8 s)."""
    import hashlib

    folder = expected_cache_folder()
    source = Path(__file__).with_name("kernel.py")
    if folder == source.resolve().parent / "__pycache__":
        return folder
    where = os.path.dirname(os.path.abspath(source))
    return folder / f"{os.path.split(where)[-1]}_{hashlib.sha1(where.encode()).hexdigest()}"


def kernel_cached_on_disk() -> bool:
    """Whether a compiled kernel that numba will load is on disk where this process looks for
    it (:func:`expected_cache_folder`): an index of the kernel written by this numba for this
    ``kernel.py`` (numba keys it by the source's sha256; the index is not unpickled, which would
    import numba). It looked in the cache folder even where that could not be written, and
    announced a compile at every run that loaded the kernel from beside the sources; and it
    took a stale index (another version of the sources in that folder) for a compiled kernel:
    a fresh clone's first run estimated 00:00, then compiled for 11.4 s."""
    import hashlib
    from importlib.metadata import PackageNotFoundError, version

    folder = kernel_index_folder()
    source = Path(__file__).with_name("kernel.py")
    try:
        stamp = hashlib.sha256(source.read_bytes()).digest()
        numba_version = version("numba")
        cpu = _cpu_name()
        return any(
            _fresh_index(nbi, stamp, numba_version, cpu)
            for nbi in folder.glob("kernel.run_chunks-*.nbi")
        )
    except (OSError, PackageNotFoundError):
        return False


def _cpu_name() -> bytes | None:
    """The CPU numba compiles for (``$NUMBA_CPU_NAME``, else LLVM's host CPU, e.g. ``znver5``):
    numba keys a cached kernel by it too, so one compiled on another machine is compiled again
    (a session's machine changed from Zen 3 to Zen 5: its first run estimated 00:00, then
    compiled). None where llvmlite cannot say. As numba's codegen: the variable whenever it is
    set, even empty (numba then keys by ``''``)."""
    name = os.environ.get("NUMBA_CPU_NAME")
    if name is None:
        try:
            from llvmlite import binding

            name = str(binding.get_host_cpu_name())
        except Exception:
            return None
    return name.encode()


def _fresh_index(nbi: Path, stamp: bytes, numba_version: str, cpu: bytes | None = None) -> bool:
    """Whether numba's index ``nbi`` (a pickled version string, then the pickled ``(source
    stamp, overloads)``, each overload keyed with the CPU it was compiled for) was written by
    ``numba_version`` for the sources of sha256 ``stamp`` and holds a kernel for ``cpu``. The
    CPU is matched as numba keys it, the whole pickled string right after the process's target
    triple (numba's magic tuple: triple, CPU, features), not as bytes anywhere in the index:
    ``skylake`` is not ``skylake-avx512``, nor ``x`` a part of ``x86_64``, nor an empty
    ``$NUMBA_CPU_NAME`` any empty string."""
    import pickle

    try:
        with nbi.open("rb") as f:
            if pickle.load(f) != numba_version:
                return False
            data = f.read()
    except Exception:  # unreadable, truncated: numba would recompile too
        return False
    if stamp not in data:
        return False
    if cpu is None:
        return True
    names = _pickled_str(cpu)
    triple = _process_triple()
    if triple is None:
        return any(name in data for name in names)
    return any(
        t + memo + name in data
        for t in _pickled_str(triple)
        for memo in (b"\x94", b"")  # pickle's MEMOIZE after the triple (protocol 4 and up)
        for name in names
    )


@functools.cache
def _process_triple() -> bytes | None:
    """The target triple numba keys a compiled kernel by with its CPU (``x86_64-unknown-linux-
    gnu``: llvmlite's process triple, as numba's codegen takes it), or None where llvmlite
    cannot say; the process's own, asked once (:func:`_fresh_index` asks it per index file)."""
    try:
        from llvmlite import binding

        return str(binding.get_process_triple()).encode()
    except Exception:
        return None


def _pickled_str(text: bytes) -> tuple[bytes, ...]:
    """The forms pickle writes the str of UTF-8 ``text`` in (protocols 1-5): SHORT_BINUNICODE
    (under 256 bytes) and BINUNICODE, each opcode with the length before the bytes."""
    n = len(text)
    forms = [b"X" + n.to_bytes(4, "little") + text]
    if n < 256:
        forms.append(b"\x8c" + bytes([n]) + text)
    return tuple(forms)


def kernel_loaded() -> bool:
    """Whether this process has the kernel compiled or loaded already."""
    from sim_backend.dem.kernel import run_chunks

    return bool(run_chunks.signatures)


def set_compile_reporter(reporter: CompileReporter | None) -> CompileReporter | None:
    """Set who hears of a first-use compilation; returns the previous reporter."""
    global _REPORTER
    old, _REPORTER = _REPORTER, reporter
    return old


def announce_if_cold() -> bool:
    """Tell the reporter now, before the first run is set up, when no compiled kernel is on disk
    (the notice then comes within the first seconds of a command, not when the first point is
    reached); :func:`compile_notice` then reports only the progress and the end."""
    global _ANNOUNCED
    reporter = _REPORTER
    if reporter is None or _ANNOUNCED or kernel_cached_on_disk():
        return False
    import sys

    # the kernel not imported yet: nothing compiled in this process (and no numba loaded
    # before the notice is out)
    if "sim_backend.dem.kernel" in sys.modules and kernel_loaded():
        return False
    _ANNOUNCED = True
    reporter("start", 0.0, expected_cache_folder(), True)
    return True


@contextmanager
def compile_notice(delay_s: float = 1.0, tick_s: float = 1.0) -> Iterator[None]:
    """Wrap the kernel's first call: report at once when nothing is on disk (a compilation),
    after ``delay_s`` otherwise (a stale cache compiles too; a fresh one loads in well under
    that), then every ``tick_s`` and at the end."""
    reporter = _REPORTER
    global _ANNOUNCED
    if reporter is None or kernel_loaded():
        yield
        return
    cold = not kernel_cached_on_disk()
    folder = kernel_cache_in_use()
    t0 = time.monotonic()
    started = threading.Event()

    def watch(stop: threading.Event) -> None:
        if stop.wait(0.0 if cold else delay_s):
            return
        started.set()
        if not _ANNOUNCED:
            reporter("start", time.monotonic() - t0, folder, cold)
        while not stop.wait(tick_s):
            reporter("tick", time.monotonic() - t0, folder, cold)

    try:
        with beside(watch, "biafc-compile-notice"):
            yield
    finally:
        if started.is_set():
            reporter("done", time.monotonic() - t0, folder, cold)
        _ANNOUNCED = False


def stale_compiled_files(
    folder: Path, current: dict[str, int], tag: str, sources: Path | None = None
) -> list[Path]:
    """The files in ``folder`` that numba wrote for an earlier source: an index
    ``<stem>-<line>.<tag>.nbi`` or data ``<stem>-<line>.<tag>.<n>.nbc`` of a function of ``current``
    (its stem, ``"kernel.run_chunks"``, and its first line now) at another line, or of a module
    that ``sources`` (the folder of the sources cached here) no longer holds. Files of another
    Python (another ``tag``, ``"py311"``) are another interpreter's, and kept."""
    stale = []
    try:
        names = sorted(p.name for p in folder.iterdir())
    except OSError:
        return []
    for name in names:
        m = _CACHED_FILE.fullmatch(name)
        if m is None or m["tag"] != tag:
            continue
        stem, line = m["stem"], int(m["line"])
        moved = stem in current and line != current[stem]
        module = stem.split(".", 1)[0]
        gone = sources is not None and not (sources / f"{module}.py").exists()
        if moved or gone:
            stale.append(folder / name)
    return stale


def _compiled_functions() -> dict[Path, tuple[Path, dict[str, int]]]:
    """The project's cached numba functions loaded in this process: per cache folder, the folder
    of their sources and their file stems and first lines (numba's internals; empty where they
    differ)."""
    from numba.core.registry import CPUDispatcher

    found: dict[Path, tuple[Path, dict[str, int]]] = {}
    for mod_name, mod in list(sys.modules.items()):
        source = getattr(mod, "__file__", None)
        if not mod_name.startswith("sim_backend.") or not isinstance(source, str):
            continue
        for obj in list(vars(mod).values()):
            cache = getattr(obj, "_cache", None) if isinstance(obj, CPUDispatcher) else None
            index = getattr(getattr(cache, "_cache_file", None), "_index_name", None)
            folder = getattr(cache, "_cache_path", None)
            code = getattr(getattr(obj, "py_func", None), "__code__", None)
            if not (isinstance(index, str) and isinstance(folder, str) and code is not None):
                continue
            if code.co_filename != source:  # imported from another module: counted there
                continue
            m = _CACHED_FILE.fullmatch(index)
            if m and m["kind"] == "nbi":
                entry = found.setdefault(Path(folder), (Path(source).parent, {}))
                entry[1][m["stem"]] = int(m["line"])
    return found


def remove_stale_compiled() -> list[Path]:
    """Once per process (later calls do nothing): delete the files an earlier source of the
    project's loaded numba functions left in their cache folders (:func:`stale_compiled_files`);
    the deleted paths. A file that cannot be deleted stays."""
    global _SWEPT
    if _SWEPT:
        return []
    _SWEPT = True
    tag = f"py{sys.version_info.major}{sys.version_info.minor}"
    removed = []
    for folder, (sources, current) in _compiled_functions().items():
        for path in stale_compiled_files(folder, current, tag, sources):
            try:
                path.unlink()
            except OSError:
                continue
            removed.append(path)
    return removed
