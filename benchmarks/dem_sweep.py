"""The DEM amplitude sweep: the default chain, 2 directions x 64 amplitudes (linear to 4 delta0),
30 ms each, every cylinder recorded at 250 kS/s, in one batch.

Reports the wall time of the batch (``wall_s``: the best of ``REPEATS`` runs, median in
``wall_median_s``; first call's numba compilation excluded: a warm-up run compiles/loads the cache
first; velocity and drive recorded, displacement, which nobody reads here, is not) and the relative
L2 error of every cylinder's velocity against a converged reference (same code, 6th-order
composition at a 62.5 ns step) on every 8th amplitude of each direction including the largest
(``max_rel_error``).

Streaming sweeps at growing batches (issue 18), each batch size in a fresh process
(:func:`scaling_point`): B = 128, 512, 2048 trajectories (2 directions x B/2 amplitudes)
through :func:`sim_backend.dem.sweep.sweep` (far-end velocity kept in float32, blocks of 128),
and B = 128, 512 through one :func:`simulate` batch recording every cylinder's velocity in
float64 (the path that held 2.2 MB a trajectory). Per row: the time of one batch (2048
trajectories in all at every B; the better of 2 rounds),
trajectories/s, the peak memory numpy allocated during a batch (``tracemalloc``, per
trajectory); and two floors:

- ``floor_flops_s``: the kernel's floating-point operations (``benchmarks._floor.
  flops_per_step``, counted from its loops, recording included) for B trajectories over the
  machine's measured peak (independent multiply-adds at the SIMD width numba emits, 4 doubles,
  on every thread): the arithmetic floor of docs/performance.md, section 2;
  ``vs_flops_floor_best_peak``: the same against the best peak measured beside any row of the
  run (the per-row measurement varies up to 2x on a shared host);
- ``floor_instr_s``: the instruction floor (``benchmarks._floor.instruction_floor``): the same
  operations by class (multiply-adds, other vector operations, square roots) at the rates this
  machine measures for each (four-lane vectors, every thread), per pass the larger of the
  square-root unit's and the arithmetic ports' time, summed;
- ``floor_lanes_s``: the kernel's own time for 32 trajectories a thread (as many LTR as RTL:
  two chunks of 16 lanes a thread, the sweep's chunk, far end recorded) times B over their
  number: the chunks' kernel time scaled to B, i.e. what batching, output and the blocks cost
  on top of the kernel.

Time to 1e-6 and 1e-8 (:func:`accuracy_rows`): the sweep's hardest trajectory (LTR, 4 delta0),
30 ms, on the benchmark chain (contact dashpot 0.005) and the default chain (dashpot off), the
default scheme with midpoint and with Heun kicks at 2 us to 0.125 us against yoshida6 at
15.625 ns; the cheapest rung under each target and the reference's own last change.
The instruction floor by pass (:func:`floor_rows`): per step and trajectory of the streaming
sweep, each pass's operations by class, its flops floor and its instruction floor with what
bounds it, and the measured rates. The streaming sweep on one thread (:func:`one_thread_rows`):
32 trajectories on the benchmark chain and on the default chain (dashpot off), in turns with
the one-thread peak, against the flops floor of one thread.
``DEM_SWEEP_PARTS`` (comma list of ``batch``, ``floor``, ``one_thread``, ``scaling``,
``accuracy``; default all) picks the parts.
"""

from __future__ import annotations

import math
import os
import time
from typing import Any, Literal

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


def _kernel_counts(chain: dem.Chain, n_sub: int) -> tuple[int, int, int, int, bool]:
    """The arguments of ``benchmarks._floor.kernel_ops`` and ``flops_per_step`` before the
    recorded cylinders, for the default integrator with ``n_sub`` steps a sample: cylinders,
    block modes, kicks a step, ``n_sub``, contact dashpot on."""
    from sim_backend.dem.simulation import DEFAULT_INTEGRATOR, INTEGRATORS

    n_kicks = len(INTEGRATORS[DEFAULT_INTEGRATOR][2])
    return chain.n, chain.n_modes + 1, n_kicks, n_sub, chain.contact_damping_ratio > 0


def run() -> dict[str, Any]:
    parts = os.environ.get("DEM_SWEEP_PARTS", "batch,floor,one_thread,scaling,accuracy").split(",")
    out: dict[str, Any] = _batch() if "batch" in parts else {}
    if "floor" in parts:
        out.update(_floor_summary(*floor_rows()))
    if "one_thread" in parts:
        out.update(_one_thread_summary(one_thread_rows()))
    if "scaling" in parts:
        out.update(_scaling_summary(scaling_rows()))
    if "accuracy" in parts:
        out.update(_accuracy_summary(accuracy_rows()))
    return out


def _print_table(title: str, rows: list[dict[str, Any]]) -> None:
    from benchmarks.__main__ import format_table

    print(f"-- {title}")
    print(format_table(rows))


def _scaling_summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    # the peak measured beside each row varies with the shared host (5.3e10 to 1.08e11 flop/s
    # within one run on 2026-11-27): the floor is the best of them, the same for every row
    best = max(r["peak_flops_per_s"] for r in rows)
    for r in rows:
        r["vs_flops_floor_best_peak"] = r["vs_flops_floor"] * best / r["peak_flops_per_s"]
    _print_table("batch size: throughput, memory, floors", rows)
    sw = {r["B"]: r for r in rows if r["path"] == "sweep"}
    sim = {r["B"]: r for r in rows if r["path"] == "simulate"}
    out: dict[str, Any] = {
        f"sweep_B{b}_trajectories_per_s": r["trajectories_per_s"] for b, r in sw.items()
    }
    out.update(
        {
            "sweep_2048_over_128": sw[2048]["trajectories_per_s"] / sw[128]["trajectories_per_s"],
            "sweep_peak_MB_per_trajectory_max": max(
                r["peak_MB_per_trajectory"] for r in sw.values()
            ),
            "simulate_peak_MB_per_trajectory": max(
                r["peak_MB_per_trajectory"] for r in sim.values()
            ),
            "simulate_512_over_128": sim[512]["trajectories_per_s"]
            / sim[128]["trajectories_per_s"],
            "sweep_2048_vs_flops_floor": sw[2048]["vs_flops_floor"],
            "peak_flops_best_per_s": best,
            "sweep_2048_vs_flops_floor_best_peak": sw[2048]["vs_flops_floor_best_peak"],
            "sweep_2048_vs_instr_floor": sw[2048]["vs_instr_floor"],
            "sweep_2048_vs_lanes_floor": sw[2048]["vs_lanes_floor"],
            "scaling_table": rows,
        }
    )
    return out


def _floor_summary(rows: list[dict[str, Any]], rates: dict[str, float]) -> dict[str, Any]:
    _print_table("the sweep's floors by pass (per step and trajectory)", rows)
    print(
        "-- rates (lane operations/s, every thread): "
        + ", ".join(f"{k} {v:.3g}" for k, v in rates.items() if k != "mixed_vs_sum")
        + f"; a 50/50 mix of fma and other ops takes {rates['mixed_vs_sum']:.2f}x the summed time"
    )
    total = rows[-1]
    out: dict[str, Any] = {f"rate_{k}": v for k, v in rates.items()}
    out.update(
        {
            "floor_table": rows,
            "instr_over_flops_floor": total["instr_floor_ns"] / total["flops_floor_ns"],
        }
    )
    return out


def floor_rows() -> tuple[list[dict[str, Any]], dict[str, float]]:
    """The streaming sweep's floors by pass (far end recorded, benchmark chain, default
    integrator at 250 kS/s): per step and trajectory each pass's operations by class
    (``benchmarks._floor.kernel_ops``), flops, the time of those flops at the measured peak and
    the instruction floor with its bound (the square-root unit or the ports); the last row sums
    them. Also returns the measured rates (``benchmarks._floor.instruction_rates``) and the
    peak (``peak_flops``, flop/s: twice the multiply-add rate, which ``peak_flops`` times with
    the same kernel)."""
    from benchmarks._floor import instruction_floor, instruction_rates, kernel_ops, unneeded_flops

    chain = dem.build_chain(benchmark_chain_spec())
    drives = _drives(chain, np.array([chain.delta0_m]))
    res = dem.simulate(chain, drives, duration_s=1e-4, sample_rate_Hz=RATE_HZ)  # warm-up
    n_sub = int(res.meta["substeps_per_sample"])
    n_cyl, n_block, _, _, dashpot = counts = _kernel_counts(chain, n_sub)
    ops = kernel_ops(*counts, 1)
    rates = instruction_rates(repeats=3)
    peak = rates["peak_flops"] = 2.0 * rates["fma"]
    floor = instruction_floor(ops, rates, lane_steps=1.0)
    # the last drift's unneeded u (and u') (kernel_ops counts them, the flops do not)
    unneeded = {"pass1": unneeded_flops(n_cyl, n_block, n_sub, dashpot)}
    rows: list[dict[str, Any]] = []
    for name, c in ops.items():
        flops = 2.0 * c["fma"] + c["other"] + c["sqrt"] - unneeded.get(name, 0.0)
        rows.append(
            {
                "pass": name,
                "fma": c["fma"],
                "other": c["other"],
                "sqrt": c["sqrt"],
                "flops": flops,
                "flops_floor_ns": flops / peak * 1e9,
                "instr_floor_ns": floor[f"{name}_s"] * 1e9,
                "bound": floor[f"{name}_bound"],
            }
        )
    rows.append(
        {
            "pass": "all",
            **{k: sum(r[k] for r in rows) for k in ("fma", "other", "sqrt", "flops")},
            "flops_floor_ns": sum(r["flops_floor_ns"] for r in rows),
            "instr_floor_ns": floor["total_s"] * 1e9,
            "bound": "",
        }
    )
    return rows, rates


def _accuracy_summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    _print_table("time to accuracy (one trajectory, LTR 4 delta0, 30 ms)", rows)
    out: dict[str, Any] = {"accuracy_table": rows}
    for r in rows:
        if "target" in r:
            key = (
                f"time_to_{r['target']:.0e}_{'dashpot' if '0.005' in r['chain'] else 'nodashpot'}_s"
            )
            out[key] = r["wall_s"] if r["reached"] else None
    return out


def _batch() -> dict[str, Any]:
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


# --- the streaming sweep on one thread against one thread's floor (issue 18) -----------------

#: trajectories of the one-thread sweep (2 directions x 16 amplitudes: two chunks of 16 lanes)
ONE_THREAD_BATCH = 32
#: rounds of the one-thread comparison: each the peak, then the sweep
ONE_THREAD_ROUNDS = 9


#: the chains of the one-thread rows: the recorded benchmarks' scene and the product's default
ONE_THREAD_CHAINS = ("dashpot 0.005", "dashpot off")


def one_thread_rows(
    batch: int = ONE_THREAD_BATCH, rounds: int = ONE_THREAD_ROUNDS, duration_s: float = DURATION_S
) -> list[dict[str, Any]]:
    """The streaming sweep on one numba thread against the flops floor of one thread, in turns.

    Per round: the one-thread peak (``benchmarks._floor.peak_flops``, best of 3), then one
    :func:`sim_backend.dem.sweep.sweep` of ``batch`` trajectories (2 directions x batch/2
    amplitudes, 0.01 to 4 delta0, far end in float32, as the scaling rows) on each chain of
    :data:`ONE_THREAD_CHAINS`: the benchmark chain (contact dashpot 0.005, the recorded scene)
    and the default chain (dashpot off, what a sweep runs on unless told otherwise), so that
    every ratio compares a sweep with the peak measured right before it. One row per round and
    chain: ns per step and trajectory, the floor's (that chain's flops per step over the
    round's peak), and their ratio. A peak measured in a slow moment lowers its round's ratio
    (one run on 2026-11-27 read a median of 1.10x that way, against 2.1-2.5x in the runs beside
    it), so :func:`_one_thread_summary` reads every round against the best peak of the run, as
    the scaling rows do. Restores the thread count it found."""
    import numba

    from benchmarks._floor import flops_per_step, peak_flops
    from sim_backend.dem.spec import default_chain_spec
    from sim_backend.dem.sweep import sweep

    specs = dict(
        zip(ONE_THREAD_CHAINS, (benchmark_chain_spec(), default_chain_spec()), strict=True)
    )
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        runs = []
        for name, spec in specs.items():
            chain = dem.build_chain(spec)
            drives = _drives(chain, chain.delta0_m * np.geomspace(0.01, 4.0, batch // 2))
            first = dem.simulate(chain, drives[:2], duration_s=1e-4, sample_rate_Hz=RATE_HZ)
            n_sub = int(first.meta["substeps_per_sample"])
            steps = n_sub * math.floor(duration_s * RATE_HZ + 1e-9)
            runs.append(
                (name, chain, drives, steps, flops_per_step(*_kernel_counts(chain, n_sub), 1))
            )
        rows: list[dict[str, Any]] = []
        for r in range(rounds):
            peak = peak_flops(repeats=3)
            for name, chain, drives, steps, fps in runs:
                t0 = time.perf_counter()
                sweep(chain, drives, duration_s=duration_s, sample_rate_Hz=RATE_HZ)
                wall = time.perf_counter() - t0
                ns = wall / (steps * batch) * 1e9
                floor_ns = fps / peak * 1e9
                rows.append(
                    {
                        "round": r + 1,
                        "chain": name,
                        "wall_s": wall,
                        "ns_per_step_trajectory": ns,
                        "peak_flops_per_s": peak,
                        "floor_ns": floor_ns,
                        "vs_flops_floor": ns / floor_ns,
                    }
                )
    finally:
        numba.set_num_threads(threads)
    return rows


def _one_thread_summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The rounds against the best peak of the run (the floor is what the machine can do, not
    what it did in one moment): per row ``vs_flops_floor_best_peak``, and per chain their best
    and median; the keys without a chain's name are the benchmark chain's (the first of
    :data:`ONE_THREAD_CHAINS`), those of the others carry it (``one_thread_dashpot_off_...``)."""
    best_peak = max(r["peak_flops_per_s"] for r in rows)
    out: dict[str, Any] = {"one_thread_table": rows}
    for i, name in enumerate(dict.fromkeys(r["chain"] for r in rows)):
        mine = [r for r in rows if r["chain"] == name]
        floor_best_ns = mine[0]["floor_ns"] * mine[0]["peak_flops_per_s"] / best_peak
        for r in mine:
            r["vs_flops_floor_best_peak"] = r["ns_per_step_trajectory"] / floor_best_ns
        ns = [r["ns_per_step_trajectory"] for r in mine]
        key = "one_thread" if i == 0 else "one_thread_" + name.replace(" ", "_").replace(".", "")
        out.update(
            {
                f"{key}_ns_per_step_trajectory_best": min(ns),
                f"{key}_ns_per_step_trajectory_median": float(np.median(ns)),
                f"{key}_floor_ns_best_peak": floor_best_ns,
                f"{key}_vs_flops_floor_best_peak_best": min(ns) / floor_best_ns,
                f"{key}_vs_flops_floor_best_peak_median": float(np.median(ns)) / floor_best_ns,
            }
        )
    _print_table("the streaming sweep on one thread, in turns with the one-thread peak", rows)
    return out


# --- streaming sweeps at growing batch sizes (issue 18) --------------------------------------

#: batch sizes of the scaling table
BATCHES = (128, 512, 2048)
#: batches of the full-output path measured beside it (2048 would hold 3.8 GB)
SIMULATE_BATCHES = (128, 512)
SCALING_REPEATS = 2
#: trajectories per measurement at every batch size (sweep; the full-output path)
TRAJECTORIES = 2048
SIMULATE_TRAJECTORIES = 512

_CHILD = (
    "import json, sys\n"
    "from benchmarks.dem_sweep import scaling_point\n"
    "print(json.dumps(scaling_point(int(sys.argv[1]), sys.argv[2])))\n"
)


def scaling_point(batch: int, path: str) -> dict[str, Any]:
    """One batch size, in this (fresh) process: ``batch`` trajectories (2 directions x
    batch/2 amplitudes, 0.01 to 4 delta0), 30 ms at 250 kS/s, by ``path``:

    - ``"sweep"``: :func:`sim_backend.dem.sweep.sweep`, far-end velocity kept in float32,
      blocks of 128 (what a study keeps);
    - ``"simulate"``: one :func:`simulate` batch, every cylinder's velocity in float64.

    Every batch size runs :data:`TRAJECTORIES` trajectories in all (B = 128: 16 batches; the
    full-output path :data:`SIMULATE_TRAJECTORIES`), so that every row sees the shared host for
    as long; ``wall_s`` is the mean time of one batch in the better of ``SCALING_REPEATS``
    such rounds. Returns it, trajectories/s, the peak of the memory numpy allocated during a
    batch (``tracemalloc``, per trajectory), and the two floors of the module docstring
    measured right before (the lanes floor: best of 5; the peak before and after the batches, the
    better of the two).
    """
    import tracemalloc

    from benchmarks._floor import (
        flops_per_step,
        instruction_floor,
        instruction_rates,
        kernel_ops,
        peak_flops,
    )
    from sim_backend.dem.sweep import sweep

    chain = dem.build_chain(benchmark_chain_spec())
    amplitudes = chain.delta0_m * np.geomspace(0.01, 4.0, batch // 2)
    drives = _drives(chain, amplitudes)
    far = [chain.n]
    dem.simulate(chain, drives[:2], duration_s=1e-4, sample_rate_Hz=RATE_HZ)  # warm-up
    # lanes floor: 16 LTR + 16 RTL drives a thread = two chunks of 16 lanes a thread
    import numba

    pick = np.linspace(0, batch // 2 - 1, 16 * numba.get_num_threads()).astype(int)
    lane_set = [drives[i] for i in pick] + [drives[batch // 2 + i] for i in pick]
    chunk_s = math.inf
    for _ in range(5):
        t0 = time.perf_counter()
        res_lanes = dem.simulate(chain, lane_set, duration_s=DURATION_S, sample_rate_Hz=RATE_HZ,
                             cylinders=far, record=("velocity",))  # fmt: skip
        chunk_s = min(chunk_s, time.perf_counter() - t0)
    peak = peak_flops(repeats=2)
    rates = instruction_rates(repeats=2)
    n_sub = int(res_lanes.meta["substeps_per_sample"])
    recorded = 1 if path == "sweep" else chain.n
    counts = _kernel_counts(chain, n_sub)
    fps = flops_per_step(*counts, recorded)
    steps = n_sub * (res_lanes.time_s.size - 1)
    # the same number of trajectories (TRAJECTORIES) at every batch size: B = 128 runs 16
    # times, 2048 once, so that every row is exposed to the shared host for as long
    total = TRAJECTORIES if path == "sweep" else SIMULATE_TRAJECTORIES
    rounds = max(1, total // batch)
    walls: list[float] = []
    tm_peak = 0
    for _ in range(SCALING_REPEATS):
        t_round = 0.0
        for _ in range(rounds):
            tracemalloc.start()
            t0 = time.perf_counter()
            if path == "sweep":
                out: Any = sweep(chain, drives, duration_s=DURATION_S, sample_rate_Hz=RATE_HZ)
            else:
                out = dem.simulate(chain, drives, duration_s=DURATION_S, sample_rate_Hz=RATE_HZ,
                                   record=("velocity",))  # fmt: skip
            t_round += time.perf_counter() - t0
            tm_peak = max(tm_peak, tracemalloc.get_traced_memory()[1])
            tracemalloc.stop()
            del out
        walls.append(t_round / rounds)
    wall = min(walls)
    # the peak again after the batches: the better of the two (a shared host's neighbours come
    # and go; the floor is what the machine can do, not what it did at one moment)
    peak = max(peak, peak_flops(repeats=2))
    floor_flops_s = fps * steps * batch / peak
    instr = instruction_floor(kernel_ops(*counts, recorded), rates, steps * batch)
    floor_instr_s = instr["total_s"]
    floor_lanes_s = chunk_s * batch / len(lane_set)
    return {
        "path": path,
        "B": batch,
        "wall_s": wall,
        "trajectories_per_s": batch / wall,
        "peak_MB_per_trajectory": tm_peak / batch / 1e6,
        "rounds": rounds,
        "floor_flops_s": floor_flops_s,
        "vs_flops_floor": wall / floor_flops_s,
        "floor_instr_s": floor_instr_s,
        "vs_instr_floor": wall / floor_instr_s,
        "floor_lanes_s": floor_lanes_s,
        "vs_lanes_floor": wall / floor_lanes_s,
        "peak_flops_per_s": peak,
    }


def scaling_rows() -> list[dict[str, Any]]:
    """:func:`scaling_point` for every batch size and path, each in a fresh process."""
    import json
    import subprocess
    import sys

    rows = []
    todo = [("sweep", b) for b in BATCHES] + [("simulate", b) for b in SIMULATE_BATCHES]
    for path, batch in todo:
        out = subprocess.run(
            [sys.executable, "-c", _CHILD, str(batch), path],
            capture_output=True, text=True, check=True, timeout=900,
        )  # fmt: skip
        row = json.loads(out.stdout.strip().splitlines()[-1])
        row["load_1min"] = round(os.getloadavg()[0], 2)
        rows.append(row)
    return rows


# --- time to 1e-6 and 1e-8 (issue 18) --------------------------------------------------------

#: the ladder: (integrator, dashpot kick) at steps (s), coarse to fine
ACCURACY_LADDER: tuple[tuple[str, Literal["midpoint", "heun3"]], ...] = (
    ("blanes-moan4", "midpoint"),
    ("blanes-moan4", "heun3"),
)
ACCURACY_STEPS_S = (2e-6, 1e-6, 0.5e-6, 0.25e-6, 0.125e-6, 62.5e-9)
#: the reference: yoshida6 at these steps; its last change says how far it is converged
ACCURACY_REFERENCE_STEPS_S = (31.25e-9, 15.625e-9)
ACCURACY_TARGETS = (1e-6, 1e-8)


def accuracy_rows(duration_s: float = DURATION_S) -> list[dict[str, Any]]:
    """Time to 1e-6 and 1e-8 on the sweep's hardest trajectory (LTR, 4 delta0: contacts open
    and close), on the benchmark chain (contact dashpot 0.005) and on the default chain
    (dashpot off): for each rung of :data:`ACCURACY_LADDER` x :data:`ACCURACY_STEPS_S`, the
    worst cylinder's relative L2 error against ``yoshida6`` at 15.625 ns (``errors.rel_l2``)
    and the wall time of the trajectory run alone; per chain and target, the cheapest rung that
    reaches it (or none, and none when the reference's own change from 31.25 ns, reported
    beside it, is above the target: an error under it is not measured)."""
    from sim_backend.dem.errors import rel_l2 as rel_l2_floored
    from sim_backend.dem.spec import default_chain_spec

    rows: list[dict[str, Any]] = []
    for label, spec in (
        ("dashpot 0.005", benchmark_chain_spec()),
        ("dashpot off", default_chain_spec()),
    ):
        chain = dem.build_chain(spec)
        drive = dem.Drive(
            "ltr", "displacement", 4.0 * chain.delta0_m, burst=Burst(F_IN_HZ["ltr"], 5.0)
        )
        kw: dict[str, Any] = {
            "duration_s": duration_s,
            "sample_rate_Hz": RATE_HZ,
            "record": ("velocity",),
        }
        refs = [
            dem.simulate(chain, [drive], integrator="yoshida6", dt_s=dt, **kw).velocity
            for dt in ACCURACY_REFERENCE_STEPS_S
        ]
        ref_change = float(rel_l2_floored(refs[0], refs[1]).max())
        ladder = []
        for integrator, kick in ACCURACY_LADDER:
            for dt in ACCURACY_STEPS_S:
                walls = []
                res = None
                for _ in range(REPEATS if dt >= 0.25e-6 else 1):
                    t0 = time.perf_counter()
                    res = dem.simulate(chain, [drive], integrator=integrator, dt_s=dt,
                                       dashpot_kick=kick, **kw)  # fmt: skip
                    walls.append(time.perf_counter() - t0)
                assert res is not None
                err = float(rel_l2_floored(res.velocity, refs[1]).max())
                ladder.append(
                    (integrator + ("+heun3" if kick == "heun3" else ""), dt, err, min(walls))
                )
        for target in ACCURACY_TARGETS:
            # an error below the reference's own change is not measured: not reached
            ok = [r for r in ladder if r[2] <= target] if ref_change <= target else []
            best = min(ok, key=lambda r: r[3]) if ok else min(ladder, key=lambda r: r[2])
            rows.append(
                {
                    "chain": label,
                    "target": target,
                    "reached": bool(ok),
                    "method": best[0],
                    "dt_us": best[1] * 1e6,
                    "error": best[2],
                    "wall_s": best[3],
                    "reference_change": ref_change,
                }
            )
        for name, dt, err, wall in ladder:
            rows.append(
                {"chain": label, "method": name, "dt_us": dt * 1e6, "error": err, "wall_s": wall}
            )
    return rows
