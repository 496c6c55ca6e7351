"""Shared helpers of the simulated bench's tests."""

from __future__ import annotations

import numpy as np


def delayed(src_time_s: np.ndarray, values: np.ndarray, at_s: np.ndarray) -> np.ndarray:
    """``values`` (a DEM record on ``src_time_s``) at the times ``at_s`` by scipy's cubic spline,
    zero outside the record (the chain at rest before the trigger): the test's own reference
    for the simulated bench's delayed record, not the product's interpolation."""
    from scipy.interpolate import CubicSpline

    inside = (at_s >= src_time_s[0]) & (at_s <= src_time_s[-1])
    out = np.zeros_like(at_s, dtype=np.float64)
    out[inside] = CubicSpline(src_time_s, values)(at_s[inside])
    return out
