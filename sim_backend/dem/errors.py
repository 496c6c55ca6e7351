"""Error measures of simulated velocities: relative L2 over time, and the step-doubling
a-posteriori estimate carried by every :class:`~sim_backend.dem.simulation.SimResult`."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["FLOOR_REL", "rel_l2", "step_doubling_error"]

#: a cylinder's L2 norm used as a denominator is raised to at least this fraction of the largest
#: cylinder norm of the same drive, so that cylinders the wave never reaches (evanescent tails
#: many decades below the driven cylinder) do not turn round-off into "100 % error"
FLOOR_REL = 1.0e-3


def rel_l2(
    v: NDArray[np.float64], v_ref: NDArray[np.float64], floor_rel: float = FLOOR_REL
) -> NDArray[np.float64]:
    """Relative L2 error over time of ``v`` against ``v_ref``, per drive and cylinder.

    ``v``, ``v_ref``: ``[R, C, S]`` velocities (m/s; any unit, the result is relative).
    Returns ``[R, C]``: ``||v - v_ref|| / max(||v_ref||, floor_rel * max_c ||v_ref||)``
    (norms over the S samples).
    """
    a = np.asarray(v, dtype=np.float64)
    b = np.asarray(v_ref, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 3:
        raise ValueError(
            f"rel_l2 needs two [R, C, S] arrays of one shape, got {a.shape}, {b.shape}"
        )
    num = np.sqrt(np.sum((a - b) ** 2, axis=-1))
    den = np.sqrt(np.sum(b**2, axis=-1))
    floor = floor_rel * den.max(axis=1, keepdims=True)
    return num / np.maximum(np.maximum(den, floor), 1e-300)


def step_doubling_error(
    v_h: NDArray[np.float64], v_2h: NDArray[np.float64], order: int
) -> NDArray[np.float64]:
    """A-posteriori error of a run at step h from a rerun at step 2h (Richardson).

    ``v_h``, ``v_2h``: ``[R, C, S]`` velocities (m/s) at the same sample times from the runs at
    h and 2h; ``order``: the integrator's order p. With ``e(h) ~ c h^p``,
    ``v_h - v_2h ~ (2^p - 1) e(h)``, so the estimate of the error of ``v_h`` is
    ``rel_l2(v_2h, v_h) / (2^p - 1)``. Returns ``[R]``: the worst cylinder of each drive.
    """
    if order < 1:
        raise ValueError(f"order must be >= 1, got {order}")
    per_cylinder = rel_l2(v_2h, v_h) / (2.0**order - 1.0)
    return np.asarray(per_cylinder.max(axis=1), dtype=np.float64)
