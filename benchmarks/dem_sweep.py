"""The DEM amplitude sweep: the default chain, 2 directions x 64 amplitudes (linear to 4 delta0),
30 ms each, every cylinder recorded at 250 kS/s, in one batch.

Reports the wall time of the batch (``wall_s``: the best of ``REPEATS`` runs, median in
``wall_median_s``; first call's numba compilation excluded: a warm-up run compiles/loads the cache
first; velocity and drive recorded, displacement, which nobody reads here, is not) and the relative
L2 error of every cylinder's velocity against a converged reference (same code, 6th-order
composition at a 62.5 ns step) on every 8th amplitude of each direction including the largest
(``max_rel_error``).
"""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np

from instruments.burst import Burst
from sim_backend import dem
from sim_backend.dem.spec import benchmark_chain_spec

F_IN_HZ = {"ltr": 8.92e3, "rtl": 6.63e3}
N_AMPLITUDES = 64
DURATION_S = 30e-3
RATE_HZ = 250e3
REFERENCE = ("yoshida6", 62.5e-9)  # integrator, step (s)
REPEATS = 3


def _drives(chain: dem.Chain, amplitudes_m: np.ndarray) -> list[dem.Drive]:
    return [
        dem.Drive(
            direction=d, kind="displacement", amplitude=float(a), burst=Burst(F_IN_HZ[d], 5.0)
        )
        for d in ("ltr", "rtl")
        for a in amplitudes_m
    ]


def rel_l2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Relative L2 error over time of ``a`` against reference ``b`` ([..., S] -> [...])."""
    num = np.sqrt(np.sum((a - b) ** 2, axis=-1))
    den = np.sqrt(np.sum(b**2, axis=-1))
    return num / np.maximum(den, 1e-300)


def run() -> dict[str, Any]:
    chain = dem.build_chain(benchmark_chain_spec())
    amplitudes = chain.delta0_m * np.geomspace(0.01, 4.0, N_AMPLITUDES)
    drives = _drives(chain, amplitudes)
    # warm-up (loads the compiled kernel from numba's cache, or compiles it once)
    dem.simulate(chain, drives[:2], duration_s=1e-4, sample_rate_Hz=RATE_HZ)
    rows = []
    integrators = os.environ.get("DEM_SWEEP_INTEGRATORS", "default").split(",")
    pick = list(range(N_AMPLITUDES - 1, -1, -8))
    sub = [drives[i] for i in pick] + [drives[N_AMPLITUDES + i] for i in pick]
    sub_rows = pick + [N_AMPLITUDES + i for i in pick]
    t0 = time.perf_counter()
    ref = dem.simulate(
        chain,
        sub,
        duration_s=DURATION_S,
        sample_rate_Hz=RATE_HZ,
        integrator=REFERENCE[0],
        dt_s=REFERENCE[1],
    )
    ref_s = time.perf_counter() - t0
    out: dict[str, Any] = {}
    for name in integrators:
        walls = []
        res = None
        for _ in range(REPEATS):
            res = None  # free the last run's output (238 MB) before this run allocates its own
            t0 = time.perf_counter()
            res = dem.simulate(
                chain, drives, duration_s=DURATION_S, sample_rate_Hz=RATE_HZ, integrator=name,
                record=("velocity", "drive"),
            )  # fmt: skip
            walls.append(time.perf_counter() - t0)
        assert res is not None
        wall = min(walls)
        err = rel_l2(res.velocity[sub_rows], ref.velocity)
        row = {
            "integrator": res.meta["integrator"],
            "dt_us": res.meta["dt_s"] * 1e6,
            "wall_s": wall,
            "wall_median_s": float(np.median(walls)),
            "max_rel_error": float(err.max()),
            "median_rel_error": float(np.median(err)),
            "finite": res.meta["finite"],
        }
        rows.append(row)
        if not out:
            out.update(row)
        del res
    out.update(
        {
            "runs": len(drives),
            "cylinders": chain.n,
            "duration_s": DURATION_S,
            "sample_rate_Hz": RATE_HZ,
            "reference": f"{REFERENCE[0]} at dt {REFERENCE[1] * 1e9:g} ns on {len(sub)} runs",
            "reference_s": ref_s,
            "threads": int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count() or 1)),
            "table": rows,
        }
    )
    return out
