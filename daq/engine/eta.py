"""How long a run takes: a prior from the bench that will run it, refined from measured points.

A plan's points are of two kinds. The first point of each (direction, amplitude) *arms* a new
burst: the generator takes the new waveform and, on the simulated bench, the model computes the
chain's response to it (cached for the other cylinders); every other point only moves, settles
and records. Each kind has a prior cost in seconds (:class:`PointCosts`):

* a real bench (or a simulated one that waits in real time, ``speedup > 0``): the physical time
  of a point (settle, ``averages`` records of pre-trigger plus duration plus
  :data:`RECORD_OVERHEAD_S`, the mean stage move at the stage speed), divided by the speed-up,
  and :data:`ARM_S` for a new burst;
* the simulated bench (``speedup: 0``, nothing waits): the model's cost. Arming costs one DEM
  run of ``dem_duration`` at the integrator's step, with its step-doubling error estimate (1.5
  runs), at :data:`SECONDS_PER_MODE_STEP` per cylinder-mode and step, plus :data:`COMPILE_S`
  once when the compiled model is not cached yet; other points cost :data:`SIM_POINT_S` plus
  :data:`SIM_SAMPLE_S` per recorded sample (the emulated instruments and the noise), times the
  machine's load (:func:`load_factor`: a busy machine gives this process a share of a core).

:class:`EtaEstimator` replaces a kind's prior by the median of its measured times as soon as
one is measured (the run's very first point is left out once others of its kind exist: it
carries one-time costs such as compiling or homing), so the ETA follows the bench at hand. The
engine gives it the wall time from the end of one point to the end of the next, so what runs
between points (the progress display, the boundary checks) is counted as well.
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

__all__ = [
    "ARM_S",
    "COMPILE_S",
    "RECORD_OVERHEAD_S",
    "SECONDS_PER_MODE_STEP",
    "SIM_POINT_S",
    "SIM_SAMPLE_S",
    "EtaEstimator",
    "PointCosts",
    "arms_burst",
    "dem_run_estimate_s",
    "homing_bound",
    "homing_note",
    "load_factor",
    "model_compiled",
    "prior_costs",
]

#: wall seconds per record beyond its duration on a real bench (arming, trigger, transfer)
RECORD_OVERHEAD_S = 0.05
#: wall seconds to upload a new burst to the generator and switch its output (real bench)
ARM_S = 0.5
#: seconds of DEM per cylinder-mode and step (kernel throughput on a 2024 laptop core; the
#: measured point times replace it during a run)
SECONDS_PER_MODE_STEP = 25e-9
#: first use of the model on a machine: numba compiles the kernel (then cached on disk); measured
#: 2026-11-25 on a 2-core host under a load of 2.2-2.8: 6.3-6.6 s, and 7.4 s to the first point of
#: a cold ``run_protocol smoke`` (20-26 s before the kernel's chunks left numba's ``parallel=``;
#: docs/performance.md section 3); 2026-11-28, with the branch-free pass 2 (more code to compile),
#: a second reader measured 10.4-12.3 s at a load of 0.4-1.3
COMPILE_S = 12.0
#: simulated bench, per point and per recorded sample (emulators, noise, digitiser)
SIM_POINT_S = 2e-3
SIM_SAMPLE_S = 7e-8


@dataclass(frozen=True)
class PointCosts:
    """Prior seconds per point: ``arm_s`` extra for a point that arms a new burst, ``point_s``
    for every point; ``basis`` says where they come from (printed with the dry run)."""

    point_s: float
    arm_s: float
    basis: str
    first_extra_s: float = 0.0  # one-time cost at the first point (compiling the model)


def load_factor() -> float:
    """How much slower than on an idle machine a CPU-bound run goes now: (1-minute load average
    + 1) / cores, at least 1 (1 where the load average is not known)."""
    import os

    try:
        load = os.getloadavg()[0]
    except (AttributeError, OSError):
        return 1.0
    return max(1.0, (load + 1.0) / (os.cpu_count() or 1))


@dataclass(frozen=True)
class HomingBound:
    """The longest homing of a bench's stage before a run, from the bench file alone: ``s``
    wall seconds, ``how`` what that is (travel and speed, printed with the dry run)."""

    s: float
    how: str


def homing_bound(bench_file: Any) -> HomingBound | None:
    """How long homing the stage may take before the first point (a run homes a stage that is
    not homed), from the bench file: the whole travel at ``stage.speed``, the speed homing sets
    first. The travel is the simulated stage's ``simulation.stage_travel``; on a real bench the
    model's nominal travel (``X-LSM500A``: 500 mm), or the upper soft limit where the file
    names a microstep instead. The stage may home slower (its ``limit.approach.maxspeed``); the
    run reads that at connect and says its own bound. ``None`` on a simulated bench that does
    not wait (``speedup: 0``: homing takes no wall time there)."""
    from instruments.errors import LimitError
    from instruments.zaber import microstep_of_model

    bench = bench_file.bench
    stage = bench.stage
    speed = float(stage.speed)
    if bench.simulated:
        speedup = float(getattr(bench.simulation, "speedup", 0.0) or 0.0)
        if speedup <= 0:
            return None
        lo, hi = (float(x) for x in bench.simulation.stage_travel)
        s = (hi - lo) / speed / speedup
        return HomingBound(s, f"{(hi - lo) * 1e3:.4g} mm at {speed * 1e3:.4g} mm/s, x1/{speedup:g}")
    travel, whose = float(stage.soft_limits[1]), "the upper soft limit"
    if stage.model:
        try:
            travel, whose = microstep_of_model(stage.model, stage.resolution)[1], stage.model
        except LimitError:
            pass
    return HomingBound(
        travel / speed,
        f"{whose}: {travel * 1e3:.4g} mm at {speed * 1e3:.4g} mm/s; longer if the stage's "
        "limit.approach.maxspeed is lower",
    )


def homing_note(bench_file: Any) -> str:
    """``"; before the first point the stage homes if it is not homed: at most 20 s (...)"``, for
    a dry run's line (not in its estimate: whether the stage is homed is known only at
    connect), or "" (:func:`homing_bound`)."""
    bound = homing_bound(bench_file)
    if bound is None:
        return ""
    from daq.progress import format_minutes

    return (
        "; before the first point the stage homes if it is not homed: at most "
        f"{format_minutes(bound.s)} ({bound.how})"
    )


def arms_burst(points: Sequence[Any]) -> list[bool]:
    """For each point (``direction``, ``amplitude_index``) in order: does it arm a new burst?"""
    out, armed = [], None
    for p in points:
        key = (p.direction, p.amplitude_index)
        out.append(key != armed)
        armed = key
    return out


def dem_run_estimate_s(
    n_cylinders: int, n_modes: int, duration_s: float, dt_s: float, error_estimate: bool = True
) -> float:
    """Seconds of one DEM run: steps times cylinder-modes at :data:`SECONDS_PER_MODE_STEP`
    (the step-doubling error estimate adds a run at twice the step: half as many steps)."""
    runs = 1.5 if error_estimate else 1.0
    return runs * duration_s / dt_s * n_cylinders * (n_modes + 1) * SECONDS_PER_MODE_STEP


def model_compiled() -> bool:
    """Whether the DEM kernel is compiled and cached already (see :func:`_model_compiled`)."""
    return _model_compiled()


def _model_compiled() -> bool:
    """Whether the compiled DEM kernel is on disk where this process will look for it (the
    user's cache folder, or ``$NUMBA_CACHE_DIR``; see :mod:`sim_backend.dem.kernel_cache`), or
    loaded in this process already."""
    from sim_backend.dem.kernel_cache import kernel_cached_on_disk

    if kernel_cached_on_disk():
        return True
    import sys

    kernel = sys.modules.get("sim_backend.dem.kernel")
    return bool(kernel is not None and kernel.run_chunks.signatures)


def _dem_run_s(bench_file: Any) -> float:
    """Seconds of one DEM run of the simulated bench (its error estimate included)."""
    from sim_backend.dem.defaults import DEFAULT_DT_S, DEFAULT_INTEGRATOR

    bench = bench_file.bench
    sim = bench.simulation
    integrator = DEFAULT_INTEGRATOR if sim.dem_integrator == "default" else sim.dem_integrator
    dt = sim.dem_dt if getattr(sim, "dem_dt", None) else DEFAULT_DT_S.get(integrator, 1e-6)
    dt = min(float(dt), 1e-6)  # the step also follows the drive's sampling: never coarser
    modes = _chain_modes(bench_file)
    return dem_run_estimate_s(bench.n_cylinders, modes, float(sim.dem_duration), dt)


def _chain_modes(bench_file: Any) -> int:
    """Local-resonance modes per cylinder of the simulated bench's chain."""
    try:
        from sim_backend.dem.spec import default_chain_spec, load_chain_spec

        chain = bench_file.chain_path()
        spec = load_chain_spec(chain) if chain is not None else default_chain_spec()
        return int(spec.n_modes)
    except Exception:
        return 3


def prior_costs(protocol: Any, bench_file: Any, positions_m: Sequence[float]) -> PointCosts:
    """The prior per-point costs of ``protocol`` on the bench of ``bench_file`` (see the module
    docstring); ``positions_m``: the stage positions in measurement order (for the mean move)."""
    bench = bench_file.bench
    acq = protocol.acquisition
    records = protocol.averages * (acq.duration + acq.pre_trigger + RECORD_OVERHEAD_S)
    moves = [abs(b - a) for a, b in itertools.pairwise(positions_m)]
    move_s = (sum(moves) / len(moves) if moves else 0.0) / bench.stage.speed
    physical = protocol.settle + records + move_s
    sim = bench.simulation if bench.simulated else None
    if sim is None:
        return PointCosts(physical, ARM_S, "the bench's settle, record and stage times")
    speedup = float(getattr(sim, "speedup", 0.0) or 0.0)
    samples = protocol.averages * acq.n_samples()
    load = load_factor()
    point_s = (SIM_POINT_S + SIM_SAMPLE_S * samples) * load
    if speedup > 0:
        point_s += physical / speedup
    compile_s = 0.0 if _model_compiled() else COMPILE_S
    basis = "the model's cost on the simulated bench"
    if compile_s:
        basis += f" (the model is compiled first: about {COMPILE_S:.0f} s, once)"
    if load > 1.0:
        basis += f" (x{load:.1f} for the machine's load)"
    return PointCosts(point_s, _dem_run_s(bench_file) * load, basis, compile_s)


class EtaEstimator:
    """Time left for the points still to measure, from the priors refined by measured times.

    ``arms``: for every point to measure, in order, whether it arms a new burst.
    Call :meth:`measured` after each point with its wall time; :meth:`remaining_s` gives the
    seconds for the points after it. Both cost O(log n) and O(1) in the points measured and to
    measure: the times are kept sorted (two medians a call), and the arming points left are
    counted once. (Each call used to take the median of every time measured once per point
    left: 8.2 s of a 1,240-point run's 19.6 s on the simulated bench, growing with the square
    of the points.)"""

    def __init__(self, costs: PointCosts, arms: Sequence[bool]) -> None:
        self.costs = costs
        self.arms = list(arms)
        self._times: dict[bool, list[float]] = {True: [], False: []}  # each kept sorted
        self._first: tuple[bool, float] | None = None
        self.n_measured = 0
        #: arming points from position i on, for every i (and 0 past the end)
        self._arming_after = list(itertools.accumulate(reversed(self.arms), initial=0))[::-1]

    def total_s(self) -> float:
        """The prior of every point (what the dry run prints)."""
        return self.costs.first_extra_s + self._left_s(0)

    def _cost(self, arms: bool) -> float:
        seen = self._times[arms]
        if seen:
            n = len(seen)  # the median of the sorted times
            return seen[n // 2] if n % 2 else (seen[n // 2 - 1] + seen[n // 2]) / 2.0
        return self.costs.point_s + (self.costs.arm_s if arms else 0.0)

    def _left_s(self, start: int) -> float:
        """Seconds of the points from position ``start`` on."""
        start = min(start, len(self.arms))
        arming = self._arming_after[start]
        return arming * self._cost(True) + (len(self.arms) - start - arming) * self._cost(False)

    def measured(self, seconds: float) -> None:
        """The point at position ``n_measured`` took ``seconds`` of wall time."""
        if self.n_measured >= len(self.arms) or not math.isfinite(seconds):
            self.n_measured += 1
            return
        kind = self.arms[self.n_measured]
        if self._first is None:
            self._first = (kind, seconds)  # one-time costs: kept apart while others exist
            if self.costs.first_extra_s > 0:  # it compiled the model: not a point's rate
                # (before, its 11 s became every point's until a second of its kind: "ETA
                # 02:49" with 4 s left; a second reader)
                self.n_measured += 1
                return
            bisect.insort(self._times[kind], seconds)
        else:
            first_kind, first_s = self._first
            if first_kind == kind and self._times[kind] == [first_s]:
                self._times[kind] = []  # a second measurement of its kind: drop the first
            bisect.insort(self._times[kind], seconds)
        self.n_measured += 1

    def remaining_s(self) -> float:
        """Seconds for the points not measured yet."""
        return self._left_s(self.n_measured)
