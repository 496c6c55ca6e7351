"""The compiled step map (:mod:`tests.dem.step_map`) as the tests' independent reference
for the stability check's half-step blocks: its stage arguments for a chain window."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sim_backend.dem.kernel import drift_coefficients
from sim_backend.dem.simulation import INTEGRATORS
from sim_backend.dem.step_limit import _Window


def stages(
    win: _Window, integrator: str, h: float
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64]]:
    """The splitting's stages at step ``h`` (s) on ``win`` for :mod:`tests.dem.step_map`:
    the drift coefficients of its distinct drift lengths ([S, D, 4]), which of them each drift
    uses ([m + 1]) and the kick lengths ``b_s h`` ([m], s)."""
    _, a_w, b_w = INTEGRATORS[integrator]
    sizes = list(dict.fromkeys(a_w))
    om = win.omega.ravel()
    zeta = np.zeros_like(om)
    coef = np.stack([drift_coefficients(om, zeta, a * h) for a in sizes])
    idx = np.array([sizes.index(a) for a in a_w], dtype=np.int64)
    kick = np.asarray(b_w, dtype=np.float64) * h
    return coef, idx, kick
