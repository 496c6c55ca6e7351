"""The error estimate every DEM result carries, against its true error, and what it costs.

``simulate(..., error_estimate=True)`` reruns the batch at twice the step and stores the
step-doubling estimate of the velocity error (worst cylinder, ``meta["error_estimate_rel"]``).
For each chain (the default chain, contact dashpot off; the benchmark chain, dashpot on), each
built-in accuracy scene (``linear``, ``highamp``; 10 ms at 250 kS/s) and each (integrator, step)
of :data:`ROWS`:

- ``true``: relative L2 error over the window, worst cylinder, against the scene's converged
  reference (:func:`sim_backend.dem.converged.converged_reference`, cached in the user's cache
  folder; computed once otherwise);
- ``estimate``: the run's own estimate, or ``none`` with the reason when the step 2h is past the
  largest stable step (the rerun is refused);
- ``estimate / true``;
- ``cost``: best wall time with the estimate over best without (``REPEATS`` runs each,
  interleaved, the kernel loaded before timing).

This is the table of docs/performance.md section 1, "The error estimate carried by every result".
"""

from __future__ import annotations

import math
import os
import time
from typing import Any

import numpy as np

from sim_backend import dem
from sim_backend.dem.accuracy_scenes import AccuracyScene, builtin_scene
from sim_backend.dem.converged import converged_reference
from sim_backend.dem.errors import rel_l2
from sim_backend.dem.spec import benchmark_chain_spec, default_chain_spec

#: (integrator, step in s) measured on every scene
ROWS: tuple[tuple[str, float], ...] = (
    ("blanes-moan4", 4e-6),
    ("blanes-moan4", 2e-6),
    ("yoshida4", 1e-6),
    ("suzuki4", 1e-6),
    ("strang", 0.1e-6),
)
CHAINS = {"default": default_chain_spec, "benchmark": benchmark_chain_spec}
SCENES = ("linear", "highamp")
REPEATS = 5


def _timed_sim(
    scene: AccuracyScene, chain: dem.Chain, drive: dem.Drive, integrator: str, dt_s: float,
    estimate: bool,
) -> Any:  # fmt: skip
    """(result, wall s) of the scene (its ``chain`` and ``drive`` built) run by ``integrator``
    at ``dt_s`` (s)."""
    t0 = time.perf_counter()
    out = dem.simulate(
        chain, [drive], duration_s=scene.duration_s,
        sample_rate_Hz=scene.sample_rate_Hz, integrator=integrator, dt_s=dt_s,
        error_estimate=estimate,
    )  # fmt: skip
    return out, time.perf_counter() - t0


def run() -> dict[str, Any]:
    table: list[dict[str, Any]] = []
    ratios: list[float] = []
    costs: list[float] = []
    for chain_name, make_spec in CHAINS.items():
        for scene_name in SCENES:
            scene = builtin_scene(scene_name, chain_spec=make_spec())
            ref = converged_reference(scene)
            chain, drive = scene.chain(), scene.drive()
            for integrator, dt in ROWS:
                # the kernel and the stability verdicts loaded first, not timed
                _timed_sim(scene, chain, drive, integrator, dt, True)
                best = {True: math.inf, False: math.inf}
                res = None
                for _ in range(REPEATS):
                    for estimate in (False, True):
                        out, wall = _timed_sim(scene, chain, drive, integrator, dt, estimate)
                        best[estimate] = min(best[estimate], wall)
                        if estimate:
                            res = out
                assert res is not None
                true = float(rel_l2(res.velocity[:1], ref.velocity[None])[0].max())
                est = float(np.asarray(res.meta["error_estimate_rel"])[0])
                method = str(res.meta["error_estimate_method"])
                ratio = est / true if math.isfinite(est) and true > 0 else math.nan
                cost = best[True] / best[False]
                if math.isfinite(ratio):
                    ratios.append(ratio)
                costs.append(cost)
                table.append(
                    {
                        "chain": chain_name,
                        "scene": scene_name,
                        "integrator": integrator,
                        "step_us": dt * 1e6,
                        "true": true,
                        "estimate": est if math.isfinite(est) else method,
                        "estimate_over_true": ratio,
                        "cost": cost,
                        "wall_s": best[False],
                        "load_1min": os.getloadavg()[0],
                    }
                )
    return {
        "estimate_over_true_min": min(ratios),
        "estimate_over_true_max": max(ratios),
        "cost_min": min(costs),
        "cost_max": max(costs),
        "table": table,
    }
