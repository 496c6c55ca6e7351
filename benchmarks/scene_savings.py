"""What each scene decision saves: the full model against the planned (reduced) one.

For each decision (``modes``, ``nonlinearity``, ``time``, ``output``) one scene is run twice: with
:func:`sim_backend.dem.scene.full_plan` (every mode, the nonlinear kernel, the whole window, every
quantity) and with the plan of :func:`sim_backend.dem.scene.plan_scene` restricted to that one
decision where possible, so each row isolates one saving. Wall time: best of ``REPEATS`` (the
machine is shared); memory: peak of the Python-side allocations (``tracemalloc``, which numpy
reports to; the kernel's own per-chunk state is not counted: it is a few kB per lane). Error:
relative L2 of the reduced velocity against the full one (over the samples both hold), next to
the plan's stated bound.
"""

from __future__ import annotations

import time
import tracemalloc
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from instruments.burst import Burst
from sim_backend import dem
from sim_backend.dem.scene import (
    Scene,
    ScenePlan,
    SceneTolerances,
    full_plan,
    plan_scene,
    run_scene,
)
from sim_backend.dem.spec import benchmark_chain_spec

F_IN_HZ = {"ltr": 8.92e3, "rtl": 6.63e3}
RATE_HZ = 250e3
REPEATS = 5


def _measure(fn: Callable[[], Any]) -> tuple[Any, float, float]:
    """(result, best wall s, peak MB)."""
    best = float("inf")
    out: Any = None
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return out, best, peak / 1e6


def _drives(chain: dem.Chain, ratios: np.ndarray) -> tuple[dem.Drive, ...]:
    return tuple(
        dem.Drive(d, "displacement", float(r * chain.delta0_m), burst=Burst(F_IN_HZ[d], 5.0))
        for d in ("ltr", "rtl")
        for r in ratios
    )


def _rel(a: np.ndarray | None, b: np.ndarray | None) -> float:
    assert a is not None and b is not None
    n = min(a.shape[-1], b.shape[-1])
    a, b = a[..., :n], b[..., :n]
    ok = np.isfinite(a)  # samples after an early stop are NaN (not computed)
    return float(np.linalg.norm((a - b)[ok]) / np.linalg.norm(b[ok]))


def _row(
    decision: str, what: str, full: ScenePlan, plan: ScenePlan, bound: float | None
) -> dict[str, Any]:
    """One table row: ``full`` and ``plan`` run, timed and compared."""
    ref, t_full, m_full = _measure(lambda: run_scene(full))
    red, t_red, m_red = _measure(lambda: run_scene(plan))
    if red.velocity is not None:
        cyl = [int(c) - 1 for c in red.cylinders]
        assert ref.velocity is not None
        all_cyl = [int(c) - 1 for c in ref.cylinders]
        err = _rel(red.velocity, ref.velocity[:, [all_cyl.index(c) for c in cyl]])
    else:
        err = float("nan")
    return {
        "decision": decision,
        "scene": what,
        "full_s": t_full,
        "reduced_s": t_red,
        "time_saved": 1.0 - t_red / t_full,
        "full_MB": m_full,
        "reduced_MB": m_red,
        "memory_saved": 1.0 - m_red / m_full,
        "velocity_error": err,
        "stated_bound": float("nan") if bound is None else bound,
        "samples": int(red.time_s.size),
    }


def run() -> dict[str, Any]:
    chain = dem.build_chain(benchmark_chain_spec())
    chain6 = dem.build_chain(benchmark_chain_spec().model_copy(update={"n_modes": 6}))
    small = np.geomspace(0.001, 0.02, 8)  # x delta0: the linear regime
    # warm-up: compile / load the kernel
    dem.simulate(chain, [_drives(chain, small)[0]], duration_s=1e-4, sample_rate_Hz=RATE_HZ)
    rows = []
    no_lin = SceneTolerances(linear_error=0.0)

    # modes: J = 6 chain, 16 small drives, 10 ms, nonlinear kernel both ways
    sc = Scene(chain6, _drives(chain6, small), 10e-3, RATE_HZ)
    # planned for the linear regime, run on the nonlinear kernel: only the modes differ
    p = plan_scene(replace(sc, record=("velocity",)))
    p = replace(p, scene=sc, solver="nonlinear", stop_energy_fraction=None, record=sc.record)
    eps = p.decisions[0].error_bound
    t_c = float(np.pi * F_IN_HZ["ltr"] * sc.duration_s * (eps or 0.0))
    rows.append(_row("modes", f"J=6 -> {p.chain.n_modes}, 16 drives, 10 ms", full_plan(sc), p, t_c))

    # nonlinearity: default chain, 2 x 8 small amplitudes, 30 ms, velocity (linear modal)
    sc = Scene(chain, _drives(chain, small), 30e-3, RATE_HZ, record=("velocity",))
    p = plan_scene(sc)
    f = replace(full_plan(sc), record=sc.record)
    rows.append(
        _row("nonlinearity", "linear modal, 16 drives, 30 ms", f, p, p.decisions[1].error_bound)
    )
    one = Scene(chain, _drives(chain, small[-1:])[:1], 30e-3, RATE_HZ, record=("velocity",))
    p1 = plan_scene(one)
    f1 = replace(full_plan(one), record=one.record)
    rows.append(
        _row("nonlinearity", "linear modal, 1 drive, 30 ms", f1, p1, p1.decisions[1].error_bound)
    )

    # time: 2 um LTR (nonlinear), 100 ms window, early stop at 1e-3 of the input work
    big = _drives(chain, np.array([2e-6 / chain.delta0_m]))[:1]
    sc = Scene(chain, big, 100e-3, RATE_HZ)
    p = replace(plan_scene(sc), record=sc.record)
    rows.append(_row("time", "2 um ltr, 100 ms window, stop 1e-3", full_plan(sc), p, None))
    for what, drives in (("1 small drive", _drives(chain, small)[7:8]),
                         ("16 small drives", _drives(chain, small))):  # fmt: skip
        sc = Scene(chain, drives, 30e-3, RATE_HZ)
        p = replace(plan_scene(sc, no_lin), record=sc.record)
        rows.append(_row("time", f"{what}, 30 ms, stop 1e-3", full_plan(sc), p, None))

    # output: 2 um, 16 drives, 30 ms: 2 cylinders' velocity instead of 31 x 3 quantities
    sc = Scene(chain, _drives(chain, np.linspace(0.5, 4.0, 8)), 30e-3, RATE_HZ, (1, 31),
               ("velocity",))  # fmt: skip
    p = replace(plan_scene(sc), stop_energy_fraction=None)
    f = full_plan(replace(sc, cylinders=None))
    rows.append(_row("output", "2 of 31 cylinders, velocity only, 16 drives", f, p, 0.0))

    return {
        "chain": "default (31 cylinders, J = 3); J = 6 for the modes row",
        "sample_rate_Hz": RATE_HZ,
        "repeats": REPEATS,
        "table": rows,
    }
