"""One BLAS thread inside the model's small linear algebra.

The model's matrices are small (4x4 blocks, at most a few hundred rows for the step-stability
map): a threaded BLAS gains nothing there, and on a loaded host (a shared lab PC, a CI runner)
its threads wake up for every call and fight the other work for the cores, turning milliseconds
into seconds. :func:`one_blas_thread` limits BLAS (OpenBLAS, MKL, BLIS) to one thread for the
duration of a block, with ``threadpoolctl``, and restores the user's setting afterwards; nobody
has to know about ``OPENBLAS_NUM_THREADS``. The numba kernel's own threads are not affected.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["blas_threads", "one_blas_thread"]

_LOCK = threading.Lock()
_CONTROLLER: Any = None
_DEPTH = 0


def _controller() -> Any:
    global _CONTROLLER
    if _CONTROLLER is None:
        # scipy's wheels bring their own BLAS, loaded with scipy.linalg: load it first, so that
        # the controller, which inspects the loaded libraries once, limits it too
        import scipy.linalg  # noqa: F401
        from threadpoolctl import ThreadpoolController

        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """Run the block with BLAS limited to one thread (nested blocks share the outer limit)."""
    global _DEPTH
    with _LOCK:
        outer = _DEPTH > 0
        _DEPTH += 1
    try:
        if outer:
            yield
        else:
            with _controller().limit(limits=1, user_api="blas"):
                yield
    finally:
        with _LOCK:
            _DEPTH -= 1


def blas_threads() -> list[int]:
    """The thread counts of the loaded BLAS libraries right now (for tests and diagnostics)."""
    from threadpoolctl import threadpool_info

    return [int(lib["num_threads"]) for lib in threadpool_info() if lib["user_api"] == "blas"]
