"""A converged reference solution of an :class:`~sim_backend.dem.accuracy_scenes.AccuracyScene`,
confirmed by step halving and cached on disk.

The reference is the 6th-order composition ``yoshida6`` run at ``dt0``, ``dt0/2``, ... until the
relative L2 change of the worst cylinder's velocity between two halvings falls below
``tolerance_rel`` (or the step reaches ``min_dt_s``: then ``converged`` is False and the change
reached is reported). The finest run is the reference. It is stored as ``<digest>.npz`` in
:func:`~instruments.user_cache.cache_dir` (never inside the repository), keyed by the
scene (chain YAML, drive, window, rate) and the reference method (integrator, dt0, tolerance,
min step).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from instruments.user_cache import cache_dir
from sim_backend.dem.accuracy_scenes import AccuracyScene
from sim_backend.dem.beam import MODES_VERSION
from sim_backend.dem.errors import rel_l2
from sim_backend.dem.kernel import NUMERICS_VERSION

__all__ = ["ConvergedReference", "cache_dir", "converged_reference"]


@dataclass(frozen=True)
class ConvergedReference:
    """The converged velocity of a scene.

    velocity: ``[N, S]`` every cylinder's velocity (m/s), cylinder order #1..#N, at the
        scene's sample times. integrator, dt_s: the finest run (s). change_rel: worst-cylinder
        relative L2 change of the last halving. tolerance_rel: the target of that change.
    converged: change_rel < tolerance_rel. halvings: runs made after the first. wall_s: seconds
        spent computing it (0 when read from the cache). from_cache, path: where it lives.
    """

    velocity: NDArray[np.float64]
    integrator: str
    dt_s: float
    change_rel: float
    tolerance_rel: float
    converged: bool
    halvings: int
    wall_s: float
    from_cache: bool
    path: Path

    def summary(self) -> dict[str, object]:
        """JSON-ready description (no arrays)."""
        return {
            "integrator": self.integrator,
            "dt_s": self.dt_s,
            "change_rel": self.change_rel,
            "tolerance_rel": self.tolerance_rel,
            "converged": self.converged,
            "halvings": self.halvings,
            "wall_s": self.wall_s,
            "from_cache": self.from_cache,
            "path": str(self.path),
        }


def converged_reference(
    scene: AccuracyScene,
    *,
    integrator: str = "yoshida6",
    dt0_s: float = 0.25e-6,
    tolerance_rel: float = 2e-7,
    min_dt_s: float = 31.25e-9,
    use_cache: bool = True,
) -> ConvergedReference:
    """The scene's converged reference, from the cache or computed (then stored).

    Steps in s; ``tolerance_rel``: relative L2 change (worst cylinder) that ends the halving.
    """
    method = (
        f"{integrator}|dt0={dt0_s!r}|tol={tolerance_rel!r}|min={min_dt_s!r}"
        f"|kernel={NUMERICS_VERSION}|modes={MODES_VERSION}"
    )
    folder = cache_dir() / "dem-reference"
    path = folder / f"{scene.digest(method)}.npz"
    if use_cache and path.exists():
        try:
            with np.load(path, allow_pickle=False) as data:
                info = json.loads(str(data["info"]))
                velocity = np.asarray(data["velocity"], dtype=np.float64)
            return ConvergedReference(
                velocity=velocity,
                integrator=info["integrator"],
                dt_s=float(info["dt_s"]),
                change_rel=float(info["change_rel"]),
                tolerance_rel=float(info["tolerance_rel"]),
                converged=bool(info["converged"]),
                halvings=int(info["halvings"]),
                wall_s=0.0,
                from_cache=True,
                path=path,
            )
        except (OSError, ValueError, KeyError):
            pass  # unreadable entry: recompute and overwrite
    t0 = time.perf_counter()

    def run(dt: float) -> tuple[NDArray[np.float64], float]:
        res = scene.simulate(integrator, dt)
        return res.velocity, float(res.meta["dt_s"])

    prev, dt = run(dt0_s)
    change = float("inf")
    halvings = 0
    while dt / 2.0 >= min_dt_s * (1.0 - 1e-9):
        cur, dt = run(dt / 2.0)
        halvings += 1
        change = float(rel_l2(prev, cur).max())
        prev = cur
        if change < tolerance_rel:
            break
    ref = ConvergedReference(
        velocity=prev[0],
        integrator=integrator,
        dt_s=dt,
        change_rel=change,
        tolerance_rel=tolerance_rel,
        converged=change < tolerance_rel,
        halvings=halvings,
        wall_s=time.perf_counter() - t0,
        from_cache=False,
        path=path,
    )
    if use_cache:
        folder.mkdir(parents=True, exist_ok=True)
        info = {k: v for k, v in ref.summary().items() if k not in ("from_cache", "path", "wall_s")}
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, velocity=ref.velocity, info=np.array(json.dumps(info)))
        tmp.replace(path)
    return ref
