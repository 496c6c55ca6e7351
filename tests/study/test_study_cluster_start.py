"""A study interrupted while its LocalCluster starts leaves nothing for ``distributed``'s exit
hook (a second reader: Ctrl-C in the first second printed 28 lines of "Exception ignored in
atexit callback ... AssertionError: Status.init" after the study's clean last line)."""

from __future__ import annotations

from typing import Any

import distributed
import pytest
from distributed.deploy.spec import SpecCluster

from daq.study_runner import dask_client


class _HalfStarted:
    """What LocalCluster leaves registered when interrupted in its constructor."""

    shutdown_on_close = True
    status = "init"

    def close(self, timeout: float | None = None) -> None:
        raise AssertionError("Status.init")


def test_a_cluster_interrupted_while_starting_is_forgotten(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    half = _HalfStarted()

    def interrupted(**kw: Any) -> None:
        SpecCluster._instances.add(half)  # type: ignore[arg-type]
        raise KeyboardInterrupt

    monkeypatch.setattr(distributed, "LocalCluster", interrupted)
    with pytest.raises(KeyboardInterrupt), dask_client(2):
        pass
    assert half not in SpecCluster._instances
