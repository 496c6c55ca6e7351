"""A numba index of the DEM kernel, as numba writes it for this ``kernel.py`` and this numba
(what :func:`sim_backend.dem.kernel_cache.kernel_cached_on_disk` takes for a compiled kernel),
for tests that stand one up in a cache folder."""

from __future__ import annotations

import hashlib
import pickle
from importlib.metadata import version
from pathlib import Path


def write_fresh_index(
    path: Path, sources: bytes | None = None, numba: str | None = None, cpu: str | None = None
) -> None:
    """Write ``path`` (``kernel.run_chunks-*.nbi``): numba's version string, then the pickled
    ``(sha256 of the sources, overloads)``, its one overload keyed with the CPU it was compiled
    for; ``sources``, ``numba`` and ``cpu`` default to this kernel's, numba's and this host's."""
    from sim_backend.dem import kernel_cache

    src = sources if sources is not None else Path(kernel_cache.__file__).with_name(
        "kernel.py"
    ).read_bytes()  # fmt: skip
    host = kernel_cache._cpu_name() or b"generic"
    key = ("signature", ("x86_64-unknown-linux-gnu", cpu.encode() if cpu else host, b""))
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as f:
        pickle.dump(numba if numba is not None else version("numba"), f)
        f.write(pickle.dumps((hashlib.sha256(src).digest(), {key: "kernel.run_chunks-1.nbc"})))
