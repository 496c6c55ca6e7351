"""The bounded SWMR retry (:mod:`protocols.swmr_read`): its ctypes call into h5py's HDF5
library runs under h5py's own lock, so no other thread is inside HDF5 meanwhile."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import h5py
import pytest

import protocols.swmr_read as sr


def test_the_ctypes_call_holds_h5pys_lock(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from h5py._objects import phil

    path = tmp_path / "x.h5"
    with h5py.File(path, "w", libver="latest") as f:
        f["a"] = [1, 2, 3]
    other_thread_got_it: list[bool] = []

    def fake_set(fapl_id: Any, attempts: int) -> int:
        def probe() -> None:
            got = phil.acquire(False)
            if got:
                phil.release()
            other_thread_got_it.append(bool(got))

        t = threading.Thread(target=probe)
        t.start()
        t.join()
        return 0

    monkeypatch.setattr(sr, "_set_attempts", lambda: fake_set)
    with sr.open_swmr(path) as f:
        assert list(f["a"][...]) == [1, 2, 3]
    assert other_thread_got_it == [False]
