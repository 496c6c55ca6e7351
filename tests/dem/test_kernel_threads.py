"""The kernel's chunks on threads (``kernel.run_batch`` over the compiled ``kernel.run_chunks``):
the same bits whatever the threads, ``numba.set_num_threads`` honoured, a failure in a thread
raised in the caller, and no ``parallel=`` compilation anywhere in the kernel (numba compiles a
parallel loop's body into four libraries: a first-use compile of 20-26 s against 6.3-6.6 s)."""

from __future__ import annotations

import threading
from typing import Any

import numba
import numpy as np
import pytest

from instruments.burst import Burst
from sim_backend import dem
from sim_backend.dem import kernel, simulation, split_steps
from sim_backend.dem.spec import benchmark_chain_spec

OUTPUTS = (24, 25, 26, 27)  # vel, disp, drv, energy in run_batch's arguments


def _args() -> tuple[Any, ...]:
    """``simulate``'s kernel arguments for 20 bursts on the damped benchmark chain (both
    directions, breakpoints inside steps: the split steps run): 4 chunks of 8 lanes."""
    chain = dem.build_chain(benchmark_chain_spec())
    drives = [
        dem.Drive(
            "ltr" if r % 2 == 0 else "rtl",
            "displacement" if r % 3 else "force",
            chain.delta0_m * (0.3 + 0.2 * r) if r % 3 else 1.0 + r,
            burst=Burst(8.92e3 if r % 2 == 0 else 6.63e3, 3.0),
            delay_s=0.77e-6 + 1.3e-6 * r,
        )
        for r in range(20)
    ]
    captured: list[tuple[Any, ...]] = []
    mp = pytest.MonkeyPatch()
    mp.setattr(simulation, "run_batch", lambda *a: captured.append(a))
    try:
        dem.simulate(chain, drives, duration_s=0.2e-3, sample_rate_Hz=200e3)
    finally:
        mp.undo()
    return captured[0]


def _run(args: tuple[Any, ...], threads: int) -> tuple[list[np.ndarray], set[int]]:  # type: ignore[type-arg]
    """Outputs of ``run_batch`` on ``threads`` numba threads, and the threads that ran chunks."""
    a = list(args)
    for i in OUTPUTS:
        a[i] = np.zeros_like(a[i])
    ran: set[int] = set()
    compiled = kernel.run_chunks
    # each thread's first chunk waits for the other threads' first: on a loaded host one thread
    # could otherwise take every chunk before the next one starts (not a fault of the kernel);
    # a kernel that runs fewer threads than asked breaks the barrier (timeout) and fails
    meet = threading.Barrier(threads, timeout=60.0)

    def spy(*b: Any) -> None:
        if threading.get_ident() not in ran:
            ran.add(threading.get_ident())
            meet.wait()
        compiled(*b)

    old = numba.get_num_threads()
    mp = pytest.MonkeyPatch()
    mp.setattr(kernel, "run_chunks", spy)
    numba.set_num_threads(threads)
    try:
        kernel.run_batch(*a)
    finally:
        numba.set_num_threads(old)
        mp.undo()
    return [a[i] for i in OUTPUTS], ran


MAX_THREADS: int = numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]


@pytest.mark.skipif(MAX_THREADS < 2, reason="one numba thread on this host")
def test_chunks_on_two_threads_give_the_bits_of_one_and_set_num_threads_is_honoured() -> None:
    args = _args()
    assert args[5].shape[0] == 4  # lane_traj: four chunks
    one, ran_one = _run(args, 1)
    two, ran_two = _run(args, 2)
    assert ran_one == {threading.get_ident()}
    assert len(ran_two) == 2 and threading.get_ident() in ran_two
    assert np.abs(one[0]).max() > 0
    for a, b in zip(one, two, strict=True):
        assert np.array_equal(a, b)


def test_a_failure_in_a_chunk_thread_is_raised_in_the_caller(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def fail_on_chunk_2(first: int, stop: int, *rest: Any) -> None:
        if first <= 2 < stop:
            raise FloatingPointError("chunk 2")

    args: list[Any] = [None] * 29  # run_batch's arguments without a default
    args[5] = np.full((4, 8), -1, dtype=np.int64)  # lane_traj: four chunks
    monkeypatch.setattr(kernel, "run_chunks", fail_on_chunk_2)
    old = numba.get_num_threads()
    numba.set_num_threads(min(2, MAX_THREADS))
    try:
        with pytest.raises(FloatingPointError, match="chunk 2"):
            kernel.run_batch(*args)
    finally:
        numba.set_num_threads(old)


def test_no_kernel_function_is_compiled_with_parallel() -> None:
    """``parallel=`` (even with ``prange`` alone) made numba compile the chunk body as a gufunc
    and then link and optimise it again into the gufunc wrapper, the parallel wrapper and the
    caller: the first-use compile took 20-26 s (6.3-6.6 s without; docs/performance.md,
    section 3)."""
    found = {
        f"{module.__name__}.{name}": obj
        for module in (kernel, split_steps)
        for name, obj in vars(module).items()
        if isinstance(obj, numba.core.registry.CPUDispatcher)
    }
    assert "sim_backend.dem.kernel.run_chunks" in found
    assert [name for name, d in found.items() if d.targetoptions.get("parallel")] == []


def _chunk_width(
    monkeypatch: pytest.MonkeyPatch, threads: int, n_ltr: int, n_rtl: int, **kw: Any
) -> int:
    """The chunk width ``simulate`` gives the kernel for ``n_ltr`` + ``n_rtl`` bursts on a
    machine of ``threads`` numba threads (the kernel not run)."""
    chain = dem.build_chain(benchmark_chain_spec())
    drives = [
        dem.Drive(d, "displacement", chain.delta0_m * (0.2 + 0.01 * r), burst=Burst(f, 5.0))
        for d, f, n in (("ltr", 8.92e3, n_ltr), ("rtl", 6.63e3, n_rtl))
        for r in range(n)
    ]
    captured: list[tuple[Any, ...]] = []
    monkeypatch.setattr(simulation, "run_batch", lambda *a: captured.append(a))
    monkeypatch.setattr(simulation.numba, "get_num_threads", lambda: threads)
    dem.simulate(chain, drives, duration_s=0.1e-3, sample_rate_Hz=200e3, **kw)
    monkeypatch.undo()
    return int(captured[0][5].shape[1])  # lane_traj [chunks, W]


def test_the_chunks_of_an_early_stop_do_not_depend_on_the_threads(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The early stop stops a chunk as a whole (its lanes' recorded samples and end energies
    depend on which lanes share it), so its chunks depend on the batch alone: 32 + 32 bursts
    get chunks of 16 on 1 thread and on 8. Without it the chunks spread over the threads
    (16 on 1 thread, 8 on 8: each thread two chunks at least)."""
    stop = {"stop_energy_fraction": 1e-3}
    assert _chunk_width(monkeypatch, 1, 32, 32, **stop) == 16
    assert _chunk_width(monkeypatch, 8, 32, 32, **stop) == 16
    assert _chunk_width(monkeypatch, 1, 32, 32) == 16
    assert _chunk_width(monkeypatch, 8, 32, 32) == 8


@pytest.mark.parametrize(
    ("n_ltr", "n_rtl", "width"),
    [(16, 16, 16), (32, 0, 16), (17, 15, 8), (32, 8, 8), (32, 16, 16), (8, 7, 4), (12, 4, 8)],
)
def test_chunks_of_16_only_where_they_pad_no_more_than_5_percent(
    monkeypatch: pytest.MonkeyPatch, n_ltr: int, n_rtl: int, width: int
) -> None:
    """Chunks hold one orientation: 17 LTR + 15 RTL in chunks of 16 would run 48 lanes for 32
    trajectories (40 in chunks of 8), for a kernel only 4-7 % faster a lane."""
    assert _chunk_width(monkeypatch, 1, n_ltr, n_rtl) == width
