"""The kernel's operation counts (``benchmarks/_floor.py``: the flops and instruction floors of
``benchmarks/dem_sweep.py``) against the kernel itself: ``run_batch``'s Python source run on a
small chain with counting stand-ins for its four-lane vectors, so that every vector operation
the compiled kernel executes is counted once per lane group; and the floors' measuring kernels
on a short run."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from typing import Any

import numba
import numpy as np
import pytest

from benchmarks._floor import (
    flops_per_step,
    instruction_floor,
    instruction_rates,
    kernel_ops,
    peak_flops,
)
from instruments.burst import Burst
from sim_backend import dem
from sim_backend.dem import kernel, simulation
from sim_backend.dem.simulation import INTEGRATORS
from sim_backend.dem.spec import BENCHMARK_DAMPING, default_chain_spec

_COUNT: Counter[str] = Counter()


class _Lanes:
    """Four lanes of the pure-Python kernel; every arithmetic operation counts one ``other``."""

    __array_ufunc__ = None  # numpy scalars on the left defer to the reflected operators

    def __init__(self, x: np.ndarray) -> None:  # type: ignore[type-arg]
        self.x = x

    def _op(self, other: Any, f: Callable[[Any, Any], Any], reflected: bool = False) -> _Lanes:
        _COUNT["other"] += 1
        y = other.x if isinstance(other, _Lanes) else other
        return _Lanes(f(y, self.x) if reflected else f(self.x, y))

    def __add__(self, o: Any) -> _Lanes:
        return self._op(o, np.add)

    def __radd__(self, o: Any) -> _Lanes:
        return self._op(o, np.add, True)

    def __sub__(self, o: Any) -> _Lanes:
        return self._op(o, np.subtract)

    def __rsub__(self, o: Any) -> _Lanes:
        return self._op(o, np.subtract, True)

    def __mul__(self, o: Any) -> _Lanes:
        return self._op(o, np.multiply)

    def __rmul__(self, o: Any) -> _Lanes:
        return self._op(o, np.multiply, True)


def _vload(a: np.ndarray, i: int) -> _Lanes:  # type: ignore[type-arg]
    return _Lanes(a[i : i + 4].copy())


def _vstore(a: np.ndarray, i: int, v: _Lanes) -> None:  # type: ignore[type-arg]
    a[i : i + 4] = v.x


def _vsplat(x: float) -> _Lanes:
    return _Lanes(np.full(4, float(x)))


def _vbcast(a: np.ndarray, i: int) -> _Lanes:  # type: ignore[type-arg]
    assert i >= 0, "vbcast takes no negative index"
    return _Lanes(np.full(4, float(a[i])))


def _vfma(a: _Lanes, b: _Lanes, c: _Lanes) -> _Lanes:
    _COUNT["fma"] += 1
    return _Lanes(a.x * b.x + c.x)


def _vmax(a: _Lanes, b: _Lanes) -> _Lanes:
    _COUNT["other"] += 1
    return _Lanes(np.maximum(a.x, b.x))


def _vsqrt(a: _Lanes) -> _Lanes:
    _COUNT["sqrt"] += 1
    return _Lanes(np.sqrt(a.x))


def _counted_run(
    monkeypatch: pytest.MonkeyPatch, chain: dem.Chain, n_drives: int, **kw: Any
) -> tuple[Counter[str], dict[str, Any]]:
    """Vector operations of one ``simulate`` call run by the kernel's Python source, and the
    kernel's arguments (lane groups, substeps, samples)."""
    captured: dict[str, Any] = {}

    def capture(*args: Any) -> None:
        captured["args"] = args

    monkeypatch.setattr(simulation, "run_batch", capture)
    drives = [
        dem.Drive("ltr", "displacement", a * chain.delta0_m, burst=Burst(8.92e3, 5.0))
        for a in np.linspace(0.5, 3.0, n_drives)
    ]
    threads = numba.get_num_threads()
    numba.set_num_threads(1)  # the chunk width as on one thread: 32 drives, chunks of 16 lanes
    try:
        dem.simulate(chain, drives, duration_s=8e-6, sample_rate_Hz=250e3, **kw)
    finally:
        numba.set_num_threads(threads)
    for name in ("vload", "vstore", "vsplat", "vbcast", "vfma", "vmax", "vsqrt"):
        monkeypatch.setattr(kernel, name, globals()[f"_{name}"])
    for name, obj in list(vars(kernel).items()):
        if isinstance(obj, numba.core.registry.CPUDispatcher):
            monkeypatch.setattr(kernel, name, obj.py_func)
    _COUNT.clear()
    args = captured["args"]
    threads = numba.get_num_threads()
    numba.set_num_threads(1)  # the chunks one after the other: the counter is not thread-safe
    try:
        kernel.run_batch(*args)
    finally:
        numba.set_num_threads(threads)
    assert np.all(np.isfinite(args[24]))  # the Python kernel ran on real numbers
    lane_traj, n_sub, n_samples, far_wall = args[5], args[17], args[18], args[22]
    info = {
        "width": lane_traj.shape[1],
        "groups": lane_traj.size // 4,
        "n_sub": n_sub,
        "n_samples": n_samples,
        "far_wall": far_wall == 1,
    }
    return Counter(_COUNT), info


def _small_chain(**update: Any) -> dem.Chain:
    spec = default_chain_spec().model_copy(update={"n_cylinders": 5, "n_modes": 2, **update})
    return dem.build_chain(spec)


#: blocks of 4 modes (3 resonators, as the default chain's): pass 2 sums u' (``vel4``)
_FOUR_MODES = {"damping": BENCHMARK_DAMPING, "n_modes": 3}


@pytest.mark.parametrize(
    ("label", "update", "kick", "n_drives", "cylinders"),
    [
        ("damped, midpoint", {"damping": BENCHMARK_DAMPING}, "midpoint", 4, None),
        ("damped, Heun", {"damping": BENCHMARK_DAMPING}, "heun3", 4, [5]),
        ("damped, 16 lanes", {"damping": BENCHMARK_DAMPING}, "midpoint", 32, None),
        ("damped, 4 modes, midpoint", _FOUR_MODES, "midpoint", 4, None),
        ("damped, 4 modes, Heun, 16 lanes", _FOUR_MODES, "heun3", 32, [2]),
        ("damped, 4 modes, 8 lanes", _FOUR_MODES, "midpoint", 16, None),
        ("undamped contacts, 16 lanes", {}, "midpoint", 32, [4]),
        ("undamped contacts", {}, "midpoint", 16, [1, 3]),
        (
            "free far end, damped",
            {"damping": BENCHMARK_DAMPING, "far_end": "free"},
            "midpoint",
            4,
            None,
        ),
        (
            "free far end, Heun",
            {"damping": BENCHMARK_DAMPING, "far_end": "free"},
            "heun3",
            4,
            None,
        ),
    ],
)
def test_kernel_ops_count_what_the_kernel_executes(
    monkeypatch: pytest.MonkeyPatch,
    label: str,
    update: dict[str, Any],
    kick: str,
    n_drives: int,
    cylinders: list[int] | None,
) -> None:
    """Each class's total over a short run (2 samples of 2 steps of 6 kicks, then the last
    sample recorded) is exactly what ``kernel_ops`` says, for 5 cylinders and 3 or 4 block
    modes (u' summed in pass 1, or in pass 2), in chunks of 4, 8 and 16 lanes."""
    chain = _small_chain(**update)
    counted, info = _counted_run(
        monkeypatch, chain, n_drives, cylinders=cylinders, record=("velocity",), dashpot_kick=kick
    )
    n_kicks = len(INTEGRATORS["blanes-moan4"][2])
    n_rec = chain.n if cylinders is None else len(cylinders)
    ops = kernel_ops(
        chain.n, chain.n_modes + 1, n_kicks, info["n_sub"], chain.contact_damping_ratio > 0, n_rec,
        heun_kicks=kick == "heun3", far_wall=info["far_wall"],
    )  # fmt: skip
    steps = (info["n_samples"] - 1) * info["n_sub"]
    for cls in ("fma", "other", "sqrt"):
        per_step = sum(p[cls] for p in ops.values())
        # the last sample is recorded without a step after it
        expected = (per_step * steps + ops["record"][cls] * info["n_sub"]) * info["groups"]
        assert counted[cls] == pytest.approx(expected, abs=1e-6), (label, cls)
    assert (chain.contact_damping_ratio > 0) == ("undamped" not in label)
    assert info["width"] == (16 if "16 lanes" in label else 8 if n_drives >= 16 else 4)
    assert (chain.n_modes + 1 == 4) == ("4 modes" in label)


def test_flops_per_step_by_hand() -> None:
    """Two cylinders, one mode (the rigid one), one kick a step, one step a sample, undamped,
    nothing recorded, far wall: pass 1 per drift 2 x (1 + 4 x 2 + 2) = 22 flops (no u' without
    a dashpot), two drifts (the last one's u, 2 x 2 flops, not needed); pass 2: actuator 19 + 2
    + 1, one contact between the cylinders 4 + 1, the far wall 6 + 2 + 1, two forces on the
    cylinders: 38. With a dashpot pass 1 has u' too: 2 x (1 + 5 x 2 + 2) = 26 a drift."""
    assert flops_per_step(2, 1, 1, 1, False, 0) == 22 + (22 - 4) + 38
    assert kernel_ops(2, 1, 1, 1, True, 0)["pass1"]["fma"] == 2 * 2 * 5
    ops = kernel_ops(2, 1, 1, 1, False, 0)
    assert ops["pass2"] == {"fma": 2.0, "other": 31.0, "sqrt": 3.0}
    # the benchmark's sweep (31 cylinders, K = 4, 6 kicks, 2 steps a sample, damped, every
    # cylinder recorded): 13 445.5 in all, 13 625.5 before the overlaps came from shifted
    # displacements (one add less per contact between cylinders and kick)
    assert flops_per_step(31, 4, 6, 2, True, 31) == 13445.5


def test_instruction_floor_takes_the_slower_unit_per_pass() -> None:
    ops = {
        "a": {"fma": 8.0, "other": 4.0, "sqrt": 1.0},  # ports 8/8 + 4/4 = 2 s, sqrt 1/2 s
        "b": {"fma": 0.0, "other": 4.0, "sqrt": 6.0},  # ports 1 s, sqrt 3 s
    }
    rates = {"fma": 8.0, "other": 4.0, "sqrt": 2.0}
    floor = instruction_floor(ops, rates, lane_steps=10.0)
    assert floor["a_s"] == pytest.approx(20.0) and floor["a_bound"] == "ports"
    assert floor["b_s"] == pytest.approx(30.0) and floor["b_bound"] == "sqrt"
    assert floor["total_s"] == pytest.approx(50.0)


def test_floor_kernels_run() -> None:
    """The measuring kernels, briefly: positive finite rates, a square root slower than a
    multiply-add, and a multiply-add peak in flops consistent with the vector FMA rate."""
    rates = instruction_rates(repeats=1, scale=0.01)
    for key in ("sqrt", "other", "fma", "mixed_vs_sum"):
        assert math.isfinite(rates[key]) and rates[key] > 0, key
    assert rates["sqrt"] < rates["fma"]
    assert peak_flops(repeats=1, n_iter=10_000) > 0


@pytest.mark.parametrize(
    ("body", "counts"),
    [
        ("_sqrt_lanes", {"vsqrtpd": 8, "vaddpd": 8}),
        ("_other_lanes", {"vmaxpd": 8, "vaddpd": 8, "vmulpd": 4}),
        ("_fma_lanes", {"vfmadd": 10}),
        ("_mixed_lanes", {"vfmadd": 8, "vmaxpd": 4, "vaddpd": 4}),
    ],
)
def test_rate_kernels_issue_the_instructions_they_count(body: str, counts: dict[str, int]) -> None:
    """The loop of each measuring kernel is the instructions its rate divides by, one each (a
    lane-wise max of two variables would be a max, a compare and a blend: not what the
    kernel's max against 0 costs); at most a multiple of them if LLVM unrolls."""
    import benchmarks._floor as floor

    fn = numba.njit(getattr(floor, body).py_func)  # compiled here: cached code has no assembly
    fn(2, 0)
    asm = fn.inspect_asm(fn.signatures[0])
    assert "vblendv" not in asm and "vcmpunord" not in asm
    # the hottest loop: the basic block holding the most of the first counted instruction
    blocks = asm.split("\n.LBB")
    first = next(iter(counts))
    loop = max(blocks, key=lambda b: b.count(first))
    n = loop.count(first) // counts[first]
    assert n >= 1
    for ins, c in counts.items():
        assert loop.count(ins) == c * n, (body, ins, loop.count(ins), c * n)
    # held in registers: a vector spilled to the stack would make the rate depend on the
    # stack's alignment, which differs from one process to the next
    assert "(%rsp)" not in loop, body


def test_peak_is_the_multiply_add_rate_kernel(monkeypatch: pytest.MonkeyPatch) -> None:
    """``peak_flops`` times the multiply-add rate kernel (10 four-lane ``vfmadd`` an iteration,
    checked above; 2 flops each) on every thread. Its former kernel, a loop over an array whose
    vectors went to and from the stack, read 20-59 Gflop/s from one process to the next on one
    core."""
    import benchmarks._floor as floor

    timed: list[tuple[object, int, int]] = []

    def one_second(kernel: object, n_iter: int, n_par: int, repeats: int) -> float:
        timed.append((kernel, n_iter, n_par))
        return 1.0

    monkeypatch.setattr(floor, "_best_s", one_second)
    n_par = numba.get_num_threads()
    assert floor.peak_flops(repeats=1, n_iter=1000) == 2 * 10 * 4 * 1000 * n_par
    assert timed == [(floor._vfma_kernel, 1000, n_par)]


def test_one_thread_sweep_rows_pair_each_sweep_with_its_peak() -> None:
    """``benchmarks.dem_sweep.one_thread_rows``, briefly: one row per round with the sweep's
    time per step and trajectory over the floor measured right before it, on one thread, and
    the thread count restored afterwards."""
    from benchmarks.dem_sweep import one_thread_rows

    threads = numba.get_num_threads()
    rows = one_thread_rows(batch=4, rounds=2, duration_s=1e-3)
    assert numba.get_num_threads() == threads
    assert [(r["round"], r["chain"]) for r in rows] == [
        (1, "dashpot 0.005"), (1, "dashpot off"), (2, "dashpot 0.005"), (2, "dashpot off")
    ]  # fmt: skip
    # the default chain (no dashpot) has fewer operations a step: a lower floor at one peak
    assert rows[1]["floor_ns"] < rows[0]["floor_ns"]
    for r in rows:
        assert r["ns_per_step_trajectory"] > 0 and r["floor_ns"] > 0
        assert r["vs_flops_floor"] == pytest.approx(r["ns_per_step_trajectory"] / r["floor_ns"])


def test_one_thread_summary_reads_every_round_against_the_best_peak() -> None:
    """A round whose peak was measured in a slow moment has a low ratio of its own; the summary
    reads every round against the run's best peak instead (it took the rounds' own ratios
    before, and one run read 1.10x that way beside runs of 2.1-2.5x)."""
    from benchmarks.dem_sweep import _one_thread_summary

    fps = 13_000.0
    rows: list[dict[str, Any]] = [
        {"round": 1, "chain": "c", "ns_per_step_trajectory": 500.0, "peak_flops_per_s": 5e10},
        {"round": 2, "chain": "c", "ns_per_step_trajectory": 520.0, "peak_flops_per_s": 1e10},
    ]
    for r in rows:  # the second round's peak was measured in a slow moment
        r["floor_ns"] = fps / r["peak_flops_per_s"] * 1e9
        r["vs_flops_floor"] = r["ns_per_step_trajectory"] / r["floor_ns"]
    out = _one_thread_summary(rows)
    floor_ns = fps / 5e10 * 1e9  # 260 ns
    assert out["one_thread_floor_ns_best_peak"] == pytest.approx(floor_ns)
    assert out["one_thread_vs_flops_floor_best_peak_best"] == pytest.approx(500.0 / floor_ns)
    assert out["one_thread_vs_flops_floor_best_peak_median"] == pytest.approx(510.0 / floor_ns)
    assert [r["vs_flops_floor_best_peak"] for r in rows] == pytest.approx(
        [500.0 / floor_ns, 520.0 / floor_ns]
    )


def test_one_thread_summary_reads_each_chain_on_its_own() -> None:
    """Rows of two chains: each chain's best and median against its own floor at the run's best
    peak; the first chain's keys have no name (as before the second chain was measured)."""
    from benchmarks.dem_sweep import _one_thread_summary

    rows = []
    for r, peak in ((1, 5e10), (2, 4e10)):
        for chain, fps, ns in (
            ("dashpot 0.005", 13_000.0, 500.0),
            ("dashpot off", 11_000.0, 440.0),
        ):
            floor_ns = fps / peak * 1e9
            rows.append({"round": r, "chain": chain, "ns_per_step_trajectory": ns + r,
                         "peak_flops_per_s": peak, "floor_ns": floor_ns,
                         "vs_flops_floor": (ns + r) / floor_ns})  # fmt: skip
    out = _one_thread_summary(rows)
    assert out["one_thread_floor_ns_best_peak"] == pytest.approx(260.0)
    assert out["one_thread_vs_flops_floor_best_peak_best"] == pytest.approx(501.0 / 260.0)
    assert out["one_thread_dashpot_off_floor_ns_best_peak"] == pytest.approx(220.0)
    assert out["one_thread_dashpot_off_vs_flops_floor_best_peak_best"] == pytest.approx(441 / 220)
    assert out["one_thread_dashpot_off_vs_flops_floor_best_peak_median"] == pytest.approx(
        441.5 / 220.0
    )
