"""Batched sweeps that stream: many drives on one chain, keeping only what the caller asks for.

:func:`simulate` returns every recorded sample of every trajectory in float64 (2.2 MB per
trajectory for 31 cylinders over 30 ms at 250 kS/s: 4.4 GB at B = 2048, and a throughput that
drops with the batch as the output leaves the caches). A study needs a few numbers per
trajectory. :func:`sweep` runs the drives in blocks of ``block_size`` trajectories (one compiled
batch each, the same kernel and the same numbers as :func:`simulate`), records only the cylinders
asked for, and keeps per trajectory either those traces in float32 (``keep="velocity"``), or only
the metrics that ``reduce`` computes from each block (``keep="metrics"``), or both. Memory is
``block_size`` trajectories in flight plus what is kept; throughput does not depend on B.

float32 traces: a relative rounding of 6e-8, far below the integrator's error at the default
step (about 1e-5, ``benchmarks/dem_sweep.py``); ask for ``dtype=np.float64`` when comparing runs
at the 1e-8 level.

Typical use (calibration and design studies)::

    res = sweep(chain, drives, duration_s=30e-3, cylinders=[31], keep="metrics",
                reduce=band_metrics)
    res.metrics["rms_m_per_s"][:, 0]     # [R] far-end rms velocity

A reducer is any ``f(velocity [b, C, S] float64 m/s, time_s [S]) -> {name: array [b, ...]}``;
:func:`band_metrics` is the built-in one (rms, peak and peak frequency of each recorded cylinder).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from sim_backend.dem.chain import Chain
from sim_backend.dem.drive import Drive
from sim_backend.dem.simulation import DEFAULT_SAMPLE_RATE_HZ, simulate

__all__ = ["DEFAULT_BLOCK", "Reducer", "SweepResult", "band_metrics", "sweep"]

#: trajectories per compiled batch: enough lanes for every thread, output small enough to stay
#: in the caches (benchmarks/dem_sweep.py: throughput flat from B = 128 to 2048)
DEFAULT_BLOCK = 128

#: velocity [b, C, S] (m/s), time [S] (s) -> {name: [b, ...]}
Reducer = Callable[[NDArray[np.float64], NDArray[np.float64]], Mapping[str, NDArray[Any]]]


@dataclass(frozen=True)
class SweepResult:
    """Output of :func:`sweep`.

    time_s: [S] sample times (s) from the trigger.
    cylinders: [C] 1-based cylinder numbers recorded.
    velocity: [R, C, S] velocity (m/s, ``dtype``, positive from #1 towards #N) when
        ``keep`` includes the traces, else ``None``.
    metrics: name -> [R, ...] per-trajectory metrics from ``reduce`` (empty without one), and
        ``error_estimate_rel`` [R] with ``error_estimate=True``.
    meta: integrator, dt_s, blocks, block_size, wall_s, trajectories_per_s,
        kept_bytes_per_trajectory, in_flight_bytes (the largest block's float64 output),
        finite (every block finite).
    """

    time_s: NDArray[np.float64]
    cylinders: NDArray[np.int32]
    velocity: NDArray[Any] | None
    metrics: dict[str, NDArray[Any]]
    meta: dict[str, Any] = field(default_factory=dict)


def band_metrics(velocity: NDArray[np.float64], time_s: NDArray[np.float64]) -> dict[str, Any]:
    """Per trajectory and recorded cylinder ([b, C] each): ``rms_m_per_s`` (rms velocity over
    the window), ``peak_m_per_s`` (largest |v|) and ``peak_frequency_Hz`` (the largest bin of
    the Hann-windowed spectrum, refined by a parabola through it and its neighbours)."""
    n = velocity.shape[-1]
    rate = 1.0 / float(time_s[1] - time_s[0]) if time_s.size > 1 else 1.0
    spec = np.abs(np.fft.rfft(velocity * np.hanning(n), axis=-1))
    k = np.clip(np.argmax(spec, axis=-1), 1, max(spec.shape[-1] - 2, 1))
    a = np.take_along_axis(spec, (k - 1)[..., None], -1)[..., 0]
    b = np.take_along_axis(spec, k[..., None], -1)[..., 0]
    c = np.take_along_axis(spec, (k + 1)[..., None], -1)[..., 0]
    den = a - 2 * b + c
    shift = np.where(den != 0, 0.5 * (a - c) / np.where(den != 0, den, 1.0), 0.0)
    return {
        "rms_m_per_s": np.sqrt(np.mean(velocity**2, axis=-1)),
        "peak_m_per_s": np.max(np.abs(velocity), axis=-1),
        "peak_frequency_Hz": (k + shift) * rate / n,
    }


def sweep(
    chain: Chain,
    drives: Sequence[Drive],
    *,
    duration_s: float,
    sample_rate_Hz: float = DEFAULT_SAMPLE_RATE_HZ,
    cylinders: Sequence[int] | None = None,
    keep: Literal["velocity", "metrics", "both"] = "velocity",
    reduce: Reducer | None = None,
    dtype: Any = np.float32,
    block_size: int = DEFAULT_BLOCK,
    error_estimate: bool = False,
    **simulate_kwargs: Any,
) -> SweepResult:
    """Run ``drives`` on ``chain`` in blocks, keeping only what is asked for (module docstring).

    cylinders: 1-based numbers to record (default: the far end, ``[N]``).
    keep: ``"velocity"`` (the traces, in ``dtype``), ``"metrics"`` (only ``reduce``'s output)
        or ``"both"``. ``"metrics"``/``"both"`` need ``reduce``.
    block_size: trajectories per compiled batch (> 0).
    error_estimate: also keep the integrator's step-doubling error estimate of every trajectory
        as ``metrics["error_estimate_rel"]`` [R] (relative L2 of the worst recorded cylinder,
        :func:`simulate`'s ``error_estimate``; about half the run time again), and how each
        was made as ``meta["error_estimate_method"]`` [R] (``"none: ..."`` says why an
        estimate is NaN: the step 2h unstable).
    simulate_kwargs: passed to :func:`simulate` (integrator, dt_s, dashpot_kick, ...);
        ``record`` is set here.
    """
    if keep not in ("velocity", "metrics", "both"):
        raise ValueError(f"keep: 'velocity', 'metrics' or 'both', got {keep!r}")
    if keep != "velocity" and reduce is None:
        raise ValueError(f"keep={keep!r} needs a reduce function (e.g. band_metrics)")
    if block_size < 1:
        raise ValueError(f"block_size must be >= 1, got {block_size!r}")
    if len(drives) == 0:
        raise ValueError("sweep needs at least one drive")
    for bad in ("record", "cylinders"):
        if bad in simulate_kwargs:
            raise ValueError(f"sweep sets {bad!r} itself")
    cyl = [chain.n] if cylinders is None else list(cylinders)
    R = len(drives)
    n_samples = math.floor(duration_s * sample_rate_Hz + 1e-9) + 1
    traces = (
        np.empty((R, len(cyl), n_samples), dtype=dtype) if keep in ("velocity", "both") else None
    )
    metrics: dict[str, NDArray[Any]] = {}
    t0 = time.perf_counter()
    meta: dict[str, Any] = {}
    finite = True
    in_flight = 0
    methods: list[str] = []
    time_s = np.arange(n_samples) / sample_rate_Hz
    cyl_out = np.asarray(cyl, dtype=np.int32)
    n_blocks = 0
    for start in range(0, R, block_size):
        block = drives[start : start + block_size]
        res = simulate(
            chain, block, duration_s=duration_s, sample_rate_Hz=sample_rate_Hz, cylinders=cyl,
            record=("velocity",), error_estimate=error_estimate, **simulate_kwargs,
        )  # fmt: skip
        n_blocks += 1
        v = res.velocity
        in_flight = max(in_flight, v.nbytes)
        finite = finite and bool(res.meta["finite"])
        if traces is not None:
            traces[start : start + len(block), :, : v.shape[-1]] = v
        if error_estimate:
            if "error_estimate_rel" not in metrics:
                metrics["error_estimate_rel"] = np.empty(R)
            err = np.asarray(res.meta["error_estimate_rel"], dtype=np.float64)
            metrics["error_estimate_rel"][start : start + len(block)] = err
            methods += [str(res.meta.get("error_estimate_method", ""))] * len(block)
        if reduce is not None:
            for name, value in reduce(v, res.time_s).items():
                arr = np.asarray(value)
                if arr.shape[:1] != (len(block),):
                    raise ValueError(f"reduce: metric {name!r} must have {len(block)} rows")
                if name not in metrics:
                    metrics[name] = np.empty((R, *arr.shape[1:]), dtype=arr.dtype)
                metrics[name][start : start + len(block)] = arr
        meta = {k: res.meta[k] for k in ("integrator", "order", "dt_s") if k in res.meta}
        cyl_out = res.cylinders
        del res, v
    wall = time.perf_counter() - t0
    kept = (traces.nbytes if traces is not None else 0) + sum(m.nbytes for m in metrics.values())
    meta.update(
        {
            "blocks": n_blocks,
            "block_size": block_size,
            "wall_s": wall,
            "trajectories_per_s": R / wall if wall > 0 else math.inf,
            "kept_bytes_per_trajectory": kept / R,
            "in_flight_bytes": in_flight,
            "finite": finite,
        }
    )
    if error_estimate:
        meta["error_estimate_method"] = methods
    return SweepResult(time_s, cyl_out, traces, metrics, meta)
