"""A numba index of the DEM kernel, as numba writes it for this ``kernel.py`` and this numba
(what :func:`sim_backend.dem.kernel_cache.kernel_cached_on_disk` takes for a compiled kernel),
for tests that stand one up in a cache folder.

The key numba files a compiled overload under is taken from numba itself, not from the
product's :func:`~sim_backend.dem.kernel_cache._cpu_name` (a test double that asked the
product would repeat its mistakes): numba keys an overload by ``(signature,
codegen.magic_tuple(), hashes)`` (``numba/core/caching.py``, ``_index_key``), and
``magic_tuple()`` is ``(triple, CPU name, features)``, the CPU name ``config.CPU_NAME``
(``$NUMBA_CPU_NAME``, read again before each compile) when it is not None, else llvmlite's
``get_host_cpu_name()`` (``numba/core/codegen.py``, ``_get_host_cpu_name``), a ``str``."""

from __future__ import annotations

import hashlib
import pickle
from importlib.metadata import version
from pathlib import Path

_KERNEL = Path(__file__).resolve().parents[1] / "sim_backend" / "dem" / "kernel.py"


def numba_magic_tuple() -> tuple[str, str, str]:
    """``(triple, CPU name, features)`` as numba's CPU codegen would key a function it compiled
    now (its config read again first, as numba's compiler does before a compile; the features
    are fixed when the process's codegen is made, the CPU name is read at each call)."""
    from numba.core import config
    from numba.core.registry import cpu_target

    config.reload_config()
    triple, cpu, features = cpu_target.target_context.codegen().magic_tuple()
    return triple, cpu, features


def numba_cpu_name() -> str:
    """The CPU name numba keys a function compiled now by on this machine (e.g. ``znver5``)."""
    return numba_magic_tuple()[1]


def write_fresh_index(
    path: Path, sources: bytes | None = None, numba: str | None = None, cpu: str | None = None
) -> None:
    """Write ``path`` (``kernel.run_chunks-*.nbi``): numba's version string, then the pickled
    ``(sha256 of the sources, overloads)``, its one overload keyed with numba's magic tuple
    (:func:`numba_magic_tuple`); ``sources``, ``numba`` and ``cpu`` default to this kernel's,
    numba's and the CPU numba compiles for here."""
    src = sources if sources is not None else _KERNEL.read_bytes()
    triple, host, features = numba_magic_tuple()
    key = ("signature", (triple, cpu if cpu is not None else host, features), ("", ""))
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as f:
        pickle.dump(numba if numba is not None else version("numba"), f)
        f.write(pickle.dumps((hashlib.sha256(src).digest(), {key: "kernel.run_chunks-1.nbc"})))
