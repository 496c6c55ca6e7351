"""Preloaded into each worker process of the LocalCluster a study starts
(:func:`daq.study_runner.dask_client`): the worker ignores SIGINT. A Ctrl-C in the terminal
reaches every process of its group; the study (the parent) ends the cluster itself, and the
workers' own KeyboardInterrupts printed two tracebacks of about 70 lines before its one line."""

from __future__ import annotations

import signal
import threading
from typing import Any


def dask_setup(worker: Any) -> None:
    """Dask's preload hook, run in the worker's process as it starts."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
