"""Min/max decimation of long traces, so a 30 ms x 1 MS/s record draws in constant time."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["MAX_POINTS", "minmax_decimate"]

#: default number of output points (2 per bucket); a screen is ~2000 pixels wide
MAX_POINTS = 4000


def minmax_decimate(
    x: ArrayLike, y: ArrayLike, max_points: int = MAX_POINTS
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Keep each bucket's minimum and maximum so peaks survive decimation.

    Parameters
    ----------
    x, y:
        ``[S]`` abscissa (e.g. time in s, monotonic) and values (any unit).
    max_points:
        Largest number of output points (even, >= 4).

    Returns
    -------
    ``(x_out [P], y_out [P])`` with ``P <= max_points``; the input unchanged (as float64) when
    ``S <= max_points``. Within each bucket the min and max appear in time order.
    """
    xa = np.asarray(x, dtype=np.float64)
    ya = np.asarray(y, dtype=np.float64)
    if xa.shape != ya.shape or xa.ndim != 1:
        raise ValueError(f"x and y must be 1-D of one shape, got {xa.shape} and {ya.shape}")
    if max_points < 4:
        raise ValueError(f"max_points must be >= 4, got {max_points}")
    n = xa.size
    if n <= max_points:
        return xa, ya
    n_buckets = max_points // 2
    size = int(np.ceil(n / n_buckets))
    n_full = n // size
    m = n_full * size
    yb = ya[:m].reshape(n_full, size)
    xb = xa[:m].reshape(n_full, size)
    # NaN-safe: a bucket of NaN stays NaN (a gap in the line)
    filled_lo = np.where(np.isnan(yb), np.inf, yb)
    filled_hi = np.where(np.isnan(yb), -np.inf, yb)
    i_min = np.argmin(filled_lo, axis=1)
    i_max = np.argmax(filled_hi, axis=1)
    first = np.minimum(i_min, i_max)
    second = np.maximum(i_min, i_max)
    rows = np.arange(n_full)
    xo = np.empty(2 * n_full)
    yo = np.empty(2 * n_full)
    xo[0::2], xo[1::2] = xb[rows, first], xb[rows, second]
    yo[0::2], yo[1::2] = yb[rows, first], yb[rows, second]
    if m < n:  # the ragged tail bucket
        tail_y = ya[m:]
        tail_x = xa[m:]
        if np.all(np.isnan(tail_y)):
            j = np.array([0, tail_y.size - 1])
        else:
            j = np.sort(np.array([np.nanargmin(tail_y), np.nanargmax(tail_y)]))
        xo = np.concatenate([xo, tail_x[j]])
        yo = np.concatenate([yo, tail_y[j]])
    return xo, yo
