"""Absolute finite-difference steps for the calibration's log-parameters."""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from analysis.fit_jacobian import LastValue, forward_jacobian

T = np.linspace(0.0, 1.0, 50)


def _model(x: np.ndarray) -> np.ndarray:
    """Two log-parameters (a level and a decay rate), the output rounded to 1e-10 as a model
    built from rounded quantities is: a relative change below that does not show."""
    return np.round(np.exp(x[0]) * 2.0 * np.exp(-np.exp(x[1]) * 3.0 * T), 10)


DATA = _model(np.zeros(2))


def _residuals(x: np.ndarray) -> np.ndarray:
    return _model(x) - DATA


def test_a_fit_that_starts_at_the_answer_keeps_its_jacobian() -> None:
    """``diff_step`` is relative to |x|: at x = 1e-8 (log of a start value that is right) the
    step was 1e-12, the Jacobian came out 0 and the calibration's uncertainties NaN."""
    x0 = np.array([1e-8, -1e-8])
    hi = np.array([5.0, 5.0])
    scipy_rel = least_squares(_residuals, x0, diff_step=1e-4, bounds=(-hi, hi), max_nfev=3)
    assert np.all(scipy_rel.jac == 0.0)  # what the calibration had
    f = LastValue(_residuals)
    sol = least_squares(f, x0, jac=forward_jacobian(f, 1e-4, hi), bounds=(-hi, hi), max_nfev=3)
    exact = np.column_stack([DATA, DATA * (-3.0 * T)])  # d/dx of the model at x = 0
    assert np.allclose(sol.jac, exact, rtol=1e-3, atol=1e-6)
    assert np.isfinite(np.linalg.cond(sol.jac.T @ sol.jac))


def test_steps_turn_back_at_the_upper_bound_and_the_residuals_are_not_recomputed() -> None:
    calls: list[np.ndarray] = []

    def counted(x: np.ndarray) -> np.ndarray:
        calls.append(np.array(x))
        return _residuals(x)

    f = LastValue(counted)
    hi = np.array([5.0, 1e-5])  # the second coordinate cannot step up by 1e-4
    f(np.zeros(2))
    jac = forward_jacobian(f, 1e-4, hi)(np.zeros(2))
    assert len(calls) == 3  # f(x) once, then one step per coordinate
    assert calls[2][1] == -1e-4 and calls[1][0] == 1e-4
    assert np.allclose(jac[:, 1], DATA * (-3.0 * T), rtol=1e-3, atol=1e-6)
