"""The console scripts' last step: an interpreter shutdown that costs milliseconds, not a third
of a second.

When a command has finished, CPython's shutdown runs its garbage collector over every object
still alive: numba's type registries, pint's unit registry, scipy and h5py hold a few hundred
thousand of them, and walking them took 0.25-0.4 s after a warm ``run_protocol smoke.yaml`` on
the 2-core host, about 15 % of the command (docs/performance.md, section 3). :func:`settle`
collects the garbage there is now (so every
finaliser still runs, while everything it may need exists), then freezes the survivors
(:func:`gc.freeze`): shutdown's collections skip them, and they are still released one by one
as the modules are cleared. Nothing else changes: ``atexit`` handlers (the log's flush, the
stability verdicts) run as before, and the run file is closed by the command itself.

Only the console scripts call it, after their ``main`` has returned: a test or a program that
calls ``main`` in-process keeps its collector as it was.
"""

from __future__ import annotations

import gc

__all__ = ["biafc", "settle"]


def settle() -> None:
    """Collect the garbage now, then freeze the live objects for the interpreter's shutdown."""
    gc.collect()
    gc.freeze()


def biafc() -> int:
    """The ``biafc`` console script: :func:`daq.cli.biafc.main`, then :func:`settle`."""
    from daq.cli.biafc import main

    try:
        return main()
    finally:
        settle()
