"""Forward-difference Jacobians with absolute steps, for fits in log-parameters.

``scipy.optimize.least_squares(diff_step=h)`` steps by ``h * |x|``. The calibration fits
``x = log(value / start)``, which is 0 at the start and stays near 0 when the start values are
already right: there the step shrank to 1e-12 and below, a column of the Jacobian came out
exactly 0, and every uncertainty read NaN (a second reader's run of ``biafc calibrate``). In log
space an absolute step is the natural one: ``h = 1e-4`` is a 0.01 % change of the value, wherever
the fit stands.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

Residuals = Callable[[NDArray[np.float64]], NDArray[np.float64]]


class LastValue:
    """``fun`` that keeps its last value, so that a Jacobian at the same ``x`` (least_squares
    asks for it right after the residuals) does not evaluate the model again."""

    def __init__(self, fun: Residuals) -> None:
        self.fun = fun
        self._x: NDArray[np.float64] | None = None
        self._f: NDArray[np.float64] | None = None

    def __call__(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        if self._x is not None and self._f is not None and np.array_equal(x, self._x):
            return self._f
        f = np.asarray(self.fun(x), dtype=np.float64)
        self._x, self._f = np.array(x, dtype=np.float64, copy=True), f
        return f


def forward_jacobian(
    fun: LastValue, step: float, upper: NDArray[np.float64]
) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
    """``jac(x) [M, P]`` of ``fun`` by forward differences of absolute ``step`` in each
    coordinate (backwards where ``x + step`` would pass ``upper [P]``); ``P`` evaluations
    beyond ``fun(x)``, which ``fun`` usually holds already."""

    def jac(x: NDArray[np.float64]) -> NDArray[np.float64]:
        x = np.asarray(x, dtype=np.float64)
        f0 = fun(x)
        out = np.empty((f0.size, x.size))
        for i in range(x.size):
            h = step if x[i] + step <= upper[i] else -step
            xi = x.copy()
            xi[i] += h
            out[:, i] = (np.asarray(fun.fun(xi), dtype=np.float64) - f0) / h
        return out

    return jac
