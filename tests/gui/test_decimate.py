"""Min/max decimation keeps every bucket's extremes and bounds the point count."""

from __future__ import annotations

import time

import numpy as np
import pytest

from daq.gui.decimate import minmax_decimate


def test_short_trace_unchanged() -> None:
    x = np.arange(10.0)
    xo, yo = minmax_decimate(x, x**2, 100)
    assert np.array_equal(xo, x) and np.array_equal(yo, x**2)


def test_long_trace_keeps_extremes_and_is_fast() -> None:
    rate, dur = 1e6, 30e-3  # 30 ms at 1 MS/s
    t = np.arange(int(rate * dur)) / rate
    rng = np.random.default_rng(1)
    y = rng.normal(size=t.size)
    y[12345] = 50.0
    y[23456] = -60.0
    t0 = time.perf_counter()
    xo, yo = minmax_decimate(t, y, 4000)
    dt = time.perf_counter() - t0
    assert xo.size <= 4002
    assert yo.max() == 50.0 and yo.min() == -60.0
    assert np.all(np.diff(xo) >= 0)  # still in time order
    assert dt < 0.05, f"decimation of 30k samples took {dt * 1e3:.1f} ms"


def test_nan_and_shape_errors() -> None:
    y = np.full(10_000, np.nan)
    y[5000] = 1.0
    _, yo = minmax_decimate(np.arange(y.size, dtype=float), y, 100)
    assert np.nanmax(yo) == 1.0
    with pytest.raises(ValueError, match="1-D"):
        minmax_decimate(np.arange(3.0), np.arange(4.0))
