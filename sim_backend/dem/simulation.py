"""Time-domain simulation of a batch of drives on one chain: :func:`simulate`."""

from __future__ import annotations

import math
import threading
import time
import weakref
from collections.abc import Collection, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numba
import numpy as np
from numpy.typing import NDArray

from sim_backend.dem.chain import Chain
from sim_backend.dem.defaults import DEFAULT_DT_S, DEFAULT_DT_TOP_HZ, DEFAULT_INTEGRATOR
from sim_backend.dem.drive import Drive
from sim_backend.dem.errors import step_doubling_error
from sim_backend.dem.integrators import INTEGRATORS, integrator_error
from sim_backend.dem.kernel import drift_coefficients, run_batch
from sim_backend.dem.kernel_cache import compile_notice, remove_stale_compiled
from sim_backend.dem.step_limit import StepTooLargeError, check_step
from sim_backend.dem.threads import one_blas_thread

__all__ = [
    "DEFAULT_DT_S",
    "DEFAULT_INTEGRATOR",
    "DEFAULT_SAMPLE_RATE_HZ",
    "INTEGRATORS",
    "BlockModes",
    "SimResult",
    "StepTooLargeError",
    "block_modes",
    "default_step_s",
    "integrator_error",
    "simulate",
    "steps_per_sample",
]

DEFAULT_SAMPLE_RATE_HZ = 500.0e3

#: quantities :func:`simulate` can record
RECORDABLE = ("velocity", "displacement", "drive")
_RECORD_BITS = {"velocity": 1, "displacement": 2, "drive": 4}

# numba's default (workqueue) threading layer must not be entered from two threads at once
_KERNEL_LOCK = threading.Lock()


@dataclass(frozen=True)
class SimResult:
    """Output of :func:`simulate`.

    Attributes
    ----------
    time_s: [S] sample times (s), 0 = trigger.
    velocity: [R, C, S] primary-mass velocity (m/s) along the chain axis, positive from
        cylinder #1 towards #N, for drive r and recorded cylinder c.
    displacement: [R, C, S] primary-mass displacement (m), same sign convention.
    drive: [R, S] the applied drive (actuator displacement into the chain in m, or force in N).
    cylinders: [C] 1-based cylinder numbers recorded.
    meta: integrator, order, dt_s, sample_rate_Hz, wall_s, energy (per drive: input work J,
        energy residual relative to the input work; meaningful with damping off).
    """

    time_s: NDArray[np.float64]
    velocity: NDArray[np.float64]
    displacement: NDArray[np.float64]
    drive: NDArray[np.float64]
    cylinders: NDArray[np.int32]
    meta: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class BlockModes:
    """Modes of every cylinder's free block (primary + resonators), index 0 = rigid translation.

    phi0: [N, J+1] primary-mass component of the mass-normalised modes (1/sqrt(kg)).
    omega: [N, J+1] angular frequencies (rad/s), omega[:, 0] = 0.
    """

    phi0: NDArray[np.float64]
    omega: NDArray[np.float64]


def eigh(a: NDArray[np.float64], b: NDArray[np.float64]) -> tuple[NDArray[Any], NDArray[Any]]:
    """``scipy.linalg.eigh(a, b)``, imported on first use (scipy.linalg costs 0.1-0.5 s to
    import, which every command that only reads a chain would pay)."""
    from scipy.linalg import eigh as scipy_eigh

    w, v = scipy_eigh(a, b)
    return w, v


#: block modes of the chains alive in this process (a chain is immutable: computed once each)
_MODES: weakref.WeakKeyDictionary[Chain, BlockModes] = weakref.WeakKeyDictionary()


def block_modes(chain: Chain) -> BlockModes:
    """Eigen-decompose each cylinder's (J+1)-DOF block (no contacts); one BLAS thread.

    Computed once per chain object (31 small eigenproblems, about 1.2 ms on the default chain,
    which every ``simulate`` call and stability check would otherwise repeat) and kept while the
    chain lives; the arrays are read-only."""
    modes = _MODES.get(chain)
    if modes is None:
        with one_blas_thread():
            modes = _block_modes(chain)
        modes.phi0.setflags(write=False)
        modes.omega.setflags(write=False)
        _MODES[chain] = modes
    return modes


def _block_modes(chain: Chain) -> BlockModes:
    N, J = chain.n, chain.n_modes
    phi0 = np.empty((N, J + 1))
    omega = np.empty((N, J + 1))
    stiff, mass = chain.block_matrices()
    for i in range(N):
        w2, vec = eigh(stiff[i], np.diag(mass[i]))
        order = np.argsort(w2)
        w2, vec = w2[order], vec[:, order]
        w2[0] = 0.0
        vec[:, 0] = 1.0 / math.sqrt(chain.mass_kg[i])
        phi0[i] = vec[0]
        omega[i] = np.sqrt(np.maximum(w2, 0.0))
    return BlockModes(phi0, omega)


def default_step_s(chain: Chain, integrator: str = DEFAULT_INTEGRATOR) -> float:
    """The integrator's default step (s) on ``chain``: ``DEFAULT_DT_S[integrator]``, scaled down
    by ``DEFAULT_DT_TOP_HZ / f_top`` when the stiffest block mode ``f_top`` is above it (the
    accuracy rule of :func:`simulate`, the stability cases and the scene planner)."""
    f_top = float(block_modes(chain).omega.max()) / (2.0 * math.pi)
    return DEFAULT_DT_S[integrator] * min(1.0, DEFAULT_DT_TOP_HZ / f_top)


def steps_per_sample(dt_s: float, sample_rate_Hz: float) -> tuple[int, float]:
    """``(n_sub, h)``: the whole number of steps per sample period that keeps each step at most
    ``dt_s`` (s), and that step ``h = period / n_sub`` (s), as :func:`simulate` takes them."""
    period = 1.0 / sample_rate_Hz
    n_sub = max(1, math.ceil(period / dt_s - 1e-9))
    return n_sub, period / n_sub


def _scheme(a: Sequence[float]) -> tuple[list[float], list[int], int]:
    """Distinct drift sizes, the kind of each drift a_k, and the kind of the merged a_m + a_0."""
    sizes = [*a, a[-1] + a[0]]
    distinct: list[float] = []
    idx: list[int] = []
    for sz in sizes:
        for j, d in enumerate(distinct):
            if abs(d - sz) < 1e-14:
                idx.append(j)
                break
        else:
            distinct.append(sz)
            idx.append(len(distinct) - 1)
    return distinct, idx[:-1], idx[-1]


def _lanes(
    orient: NDArray[np.int64], n_threads: int = 1
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Group trajectories by orientation into chunks of W lanes (padding: -1). The kernel works
    on four lanes at once (one SIMD vector) and best on sixteen (its drifts read each
    coefficient once for four vectors: 4-7 % less time than on eight, docs/performance.md):
    W = 16 where those chunks hold at most 5 % more lanes than chunks of eight (padding) and
    give each of ``n_threads`` threads two; else 8 from 16 trajectories, else 4, so that the
    chunks still spread over the threads. A lane's result does not depend on W, except under
    the early stop (a chunk stops as a whole), for which ``simulate`` passes ``n_threads = 1``:
    the chunks then depend on the batch alone, never on the machine's threads."""
    R = orient.size
    per_orient = [int(np.count_nonzero(orient == o)) for o in (0, 1)]

    def lanes(w: int) -> int:
        return sum(-(-n // w) * w for n in per_orient)

    chunks16 = lanes(16) // 16
    if lanes(16) <= 1.05 * lanes(8) and chunks16 >= 2 * max(1, n_threads):
        W = 16
    else:
        W = 8 if R >= 16 else 4
    chunks: list[list[int]] = []
    orients: list[int] = []
    for o in (0, 1):
        idx = [int(r) for r in np.flatnonzero(orient == o)]
        for start in range(0, len(idx), W):
            part = idx[start : start + W]
            chunks.append(part + [-1] * (W - len(part)))
            orients.append(o)
    return np.asarray(chunks, dtype=np.int64), np.asarray(orients, dtype=np.int64)


def _cylinder_indices(chain: Chain, cylinders: Sequence[int] | None) -> NDArray[np.int64]:
    if cylinders is None:
        return np.arange(chain.n, dtype=np.int64)
    idx = np.asarray(list(cylinders), dtype=np.int64)
    if idx.ndim != 1 or idx.size == 0 or idx.min() < 1 or idx.max() > chain.n:
        raise ValueError(f"cylinders must be 1-based numbers in 1..{chain.n}")
    return idx - 1


def simulate(
    chain: Chain,
    drives: Sequence[Drive],
    *,
    duration_s: float,
    sample_rate_Hz: float = DEFAULT_SAMPLE_RATE_HZ,
    cylinders: Sequence[int] | None = None,
    integrator: str = "default",
    dt_s: float | None = None,
    error_estimate: bool = False,
    record: Collection[str] = RECORDABLE,
    stop_energy_fraction: float | None = None,
    stop_check_s: float = 0.5e-3,
    refuse_unstable: bool = True,
    dashpot_kick: Literal["midpoint", "heun3"] = "midpoint",
    split_at_burst_ends: bool = True,
) -> SimResult:
    """Simulate every drive of ``drives`` on ``chain`` (one compiled batch, parallel over drives).

    Parameters
    ----------
    chain: the built chain.
    drives: R drives (directions and kinds may be mixed).
    duration_s: recorded window (s) from the trigger; S = floor(duration * rate) + 1 samples.
    sample_rate_Hz: record rate (Hz); the step is the largest ``1/(rate n) <= dt_s``.
    cylinders: 1-based cylinder numbers to record (default: all).
    integrator: a key of :data:`INTEGRATORS` or ``"default"`` (:data:`DEFAULT_INTEGRATOR`).
    dt_s: the integrator step (s); default :data:`DEFAULT_DT_S` of the integrator, scaled down by
        ``DEFAULT_DT_TOP_HZ / f_top`` when the stiffest block mode ``f_top`` is above it.
        An explicit step that is linearly unstable for this chain and integrator (see
        :mod:`sim_backend.dem.step_limit`) raises :class:`StepTooLargeError` (a ``ValueError``)
        whose message gives the largest stable step (``refuse_unstable=False`` skips the check,
        to measure that such a step really blows up). The check comes first: a refused step
        loads no kernel and runs nothing.
    error_estimate: also rerun the batch at step 2h (about half the cost again) and put the
        step-doubling estimate of the velocity error in ``meta["error_estimate_rel"]`` ([R],
        relative L2 of the worst cylinder, see :func:`sim_backend.dem.errors.step_doubling_error`).
    record: the quantities to keep, a subset of :data:`RECORDABLE`; the others are not allocated
        (zero-length last axis in the result) nor computed.
    stop_energy_fraction: ``None`` (default: run the whole window) or ``eps``: stop once every
        drive is over and the energy left in the chain, ``H(t) - H_static``, is at most ``eps``
        times the input work (checked every ``stop_check_s`` s). The result is then truncated at
        the last trajectory's stop; a trajectory of the batch that stopped earlier holds NaN
        after its own stop (``meta["samples_computed"]`` [R]; ``meta["energy_left_rel"]`` [R]).
    dashpot_kick: how a kick integrates the contact dashpots, whose force depends on the
        velocities the kick changes: ``"midpoint"`` (explicit midpoint, the default) or
        ``"heun3"`` (Heun's third-order rule, one more force sweep). The midpoint's error is
        second order for ``blanes-moan4`` (the other 4th/6th-order schemes cancel it) and shows
        below an error of about 2e-6, i.e. at steps of 1 us and under (contact dashpot on; with
        it off, the default, the two rules give the same result); ``"heun3"`` keeps
        ``blanes-moan4`` fourth order there for about a quarter more run time.
    split_at_burst_ends: a step that holds a burst drive's start or end (where a moving wall's
        velocity jumps) is done as sub-steps of the same scheme between them
        (:mod:`sim_backend.dem.split_steps`); ``False`` steps over them as the kernel did before
        (an O(h) error with the contact dashpot on), for comparison.
    """
    t_wall = time.perf_counter()
    why = integrator_error(integrator)
    if why is not None:
        raise ValueError(why)
    name = DEFAULT_INTEGRATOR if integrator == "default" else integrator
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s must be > 0, got {duration_s!r}")
    if not (math.isfinite(sample_rate_Hz) and sample_rate_Hz > 0):
        raise ValueError(f"sample_rate_Hz must be > 0, got {sample_rate_Hz!r}")
    if len(drives) == 0:
        raise ValueError("simulate needs at least one drive")
    if dashpot_kick not in ("midpoint", "heun3"):
        raise ValueError(f"dashpot_kick: 'midpoint' or 'heun3', got {dashpot_kick!r}")
    order, a_w, b_w = INTEGRATORS[name]
    modes = block_modes(chain)
    dt_req = default_step_s(chain, name) if dt_s is None else float(dt_s)
    if not (math.isfinite(dt_req) and dt_req > 0):
        raise ValueError(f"dt_s must be > 0, got {dt_s!r}")
    n_sub, h = steps_per_sample(dt_req, sample_rate_Hz)
    if dt_s is not None and refuse_unstable:  # an explicit step: refused before anything runs
        check_step(chain, name, h, drives)
    return _simulate(
        chain, drives, modes, name, order, a_w, b_w, h, n_sub, t_wall,
        duration_s=duration_s, sample_rate_Hz=sample_rate_Hz, cylinders=cylinders,
        error_estimate=error_estimate, record=record,
        stop_energy_fraction=stop_energy_fraction, stop_check_s=stop_check_s,
        dashpot_kick=dashpot_kick, split_at_burst_ends=split_at_burst_ends,
    )  # fmt: skip


def _simulate(
    chain: Chain,
    drives: Sequence[Drive],
    modes: BlockModes,
    name: str,
    order: int,
    a_w: tuple[float, ...],
    b_w: tuple[float, ...],
    h: float,
    n_sub: int,
    t_wall: float,
    *,
    duration_s: float,
    sample_rate_Hz: float,
    cylinders: Sequence[int] | None,
    error_estimate: bool,
    record: Collection[str],
    stop_energy_fraction: float | None,
    stop_check_s: float,
    dashpot_kick: Literal["midpoint", "heun3"],
    split_at_burst_ends: bool,
) -> SimResult:
    """:func:`simulate` after its arguments are checked and its step chosen."""
    n_samples = math.floor(duration_s * sample_rate_Hz + 1e-9) + 1

    N, K = modes.phi0.shape
    zeta = np.full((N, K), chain.bending_damping_ratio)
    zeta[:, 0] = 0.0
    sizes, seq, merge = _scheme(a_w)
    drift = np.stack([drift_coefficients(modes.omega, zeta, s * h) for s in sizes])
    phi0 = np.stack([modes.phi0, modes.phi0[::-1]])
    omega = np.stack([modes.omega, modes.omega[::-1]])
    drift2 = np.stack([drift, drift[:, ::-1]])
    zeta2 = np.stack([zeta, zeta[::-1]])
    chi = chain.hunt_crossley_chi_s_per_m()
    chi2 = np.stack([chi, chi[::-1]])
    rest = np.stack([chain.rest_overlap_m, chain.rest_overlap_m[::-1]])
    rec = _cylinder_indices(chain, cylinders)
    rec_idx = np.stack([rec, chain.n - 1 - rec])

    R = len(drives)
    orient = np.array([0 if d.direction == "ltr" else 1 for d in drives], dtype=np.int64)
    dkind = np.array([0 if d.kind == "displacement" else 1 for d in drives], dtype=np.int64)
    src = np.array([0 if d.burst is not None else 1 for d in drives], dtype=np.int64)
    prm = np.zeros((R, 8))
    lmax = max([2] + [np.asarray(d.waveform[0]).size for d in drives if d.waveform is not None])
    tables = np.zeros((R, lmax))
    n_table = np.zeros(R, dtype=np.int64)
    for r, d in enumerate(drives):
        prm[r, 0] = d.amplitude
        prm[r, 6] = d.delay_s
        if d.burst is not None:
            b = d.burst
            T = b.duration_s
            sig = b.sigma_s
            prm[r, 1:6] = (
                b.f_center_Hz,
                T,
                sig,
                0.5 * T,
                math.exp(-((0.5 * T) ** 2) / (2 * sig**2)),
            )
        else:
            assert d.waveform is not None
            samples = np.asarray(d.waveform[0], dtype=np.float64)
            tables[r, : samples.size] = samples
            n_table[r] = samples.size
            prm[r, 7] = d.waveform[1]
    C = rec.size
    if any(q not in _RECORD_BITS for q in record):
        raise ValueError(f"record: choose from {RECORDABLE}, got {tuple(record)!r}")
    rec_flags = sum(bit for q, bit in _RECORD_BITS.items() if q in record)
    n_kept = {q: n_samples if q in record else 0 for q in RECORDABLE}  # unrequested: not allocated
    vel = np.empty((R, C, n_kept["velocity"]))
    disp = np.empty((R, C, n_kept["displacement"]))
    drv = np.empty((R, n_kept["drive"]))
    stop_every = 0
    if stop_energy_fraction is not None:
        if not (math.isfinite(stop_energy_fraction) and stop_energy_fraction > 0):
            raise ValueError(f"stop_energy_fraction must be > 0, got {stop_energy_fraction!r}")
        stop_every = max(1, round(stop_check_s * sample_rate_Hz))
    energy = np.zeros((R, 6))
    # the early stop stops a chunk as a whole: its chunks must not depend on the threads
    lane_traj, chunk_orient = _lanes(orient, 1 if stop_every > 0 else numba.get_num_threads())
    args = (
        phi0, omega, drift2, chi2, np.sum(phi0**2, axis=2), lane_traj, chunk_orient,
        dkind, src, prm, tables, n_table,
        np.asarray(b_w, dtype=np.float64), np.asarray(a_w, dtype=np.float64),
        np.asarray(seq, dtype=np.int64), int(merge),
        h, n_sub, n_samples, chain.beta_c, rest, chain.f0_N,
        1 if chain.far_end == "wall" else 0, rec_idx, vel, disp, drv, energy, zeta2,
        rec_flags, stop_every, float(stop_energy_fraction or 0.0),
        1 if dashpot_kick == "heun3" else 0, 1 if split_at_burst_ends else 0,
    )  # fmt: skip
    with _KERNEL_LOCK, compile_notice():
        run_batch(*args)
        remove_stale_compiled()  # an earlier source's compiled kernel, once per process
    n_done = energy[:, 3].astype(np.int64)
    if stop_every > 0:
        n_samples = int(n_done.max())
        vel, disp, drv = vel[..., :n_samples], disp[..., :n_samples], drv[..., :n_samples]
        for r_stop in np.flatnonzero(n_done < n_samples):
            for a in (vel[r_stop], disp[r_stop], drv[r_stop]):
                a[..., n_done[r_stop] :] = np.nan
    flip = orient == 1  # the kernel records along the chain's axis already
    work = energy[:, 2]
    gain = energy[:, 1] - energy[:, 0]
    scale = np.maximum(np.abs(work), 1e-300)
    meta: dict[str, Any] = {
        "integrator": name,
        "order": order,
        "dt_s": h,
        "substeps_per_sample": n_sub,
        "sample_rate_Hz": sample_rate_Hz,
        "damped": chain.damped,
        "dashpot_kick": dashpot_kick,
        "split_at_burst_ends": split_at_burst_ends,
        "input_work_J": work,
        "energy_gain_J": gain,
        "energy_residual_rel": (gain - work) / scale,
        # what a run file stores (one name for damped and undamped chains): the input work not
        # in the chain at the end, dissipated by damping plus the integrator's energy error
        "work_not_in_chain_rel": (work - gain) / scale,
        "finite": bool(np.all(np.isfinite(vel))),
        "momentum_end_kg_m_s": np.where(flip, -energy[:, 5], energy[:, 5]),
        "wall_s": time.perf_counter() - t_wall,
    }
    if stop_every > 0:
        meta["finite"] = bool(all(np.all(np.isfinite(vel[r, :, : n_done[r]])) for r in range(R)))
        meta["samples_computed"] = n_done
        meta["energy_left_rel"] = energy[:, 4] / scale
        meta["stop_energy_fraction"] = stop_energy_fraction
    if error_estimate and vel.shape[-1] > 0:
        # the rerun at 2h records every other sample (rate / 2 keeps n_sub, so its step is 2h)
        try:
            coarse = simulate(
                chain, drives, duration_s=(n_samples - 1) / sample_rate_Hz,
                sample_rate_Hz=sample_rate_Hz / 2.0, cylinders=cylinders, integrator=name,
                dt_s=2.0 * h, record=("velocity",), dashpot_kick=dashpot_kick,
                split_at_burst_ends=split_at_burst_ends,
            ).velocity  # fmt: skip
            n_c = min(coarse.shape[-1], (vel.shape[-1] + 1) // 2)
            fine = vel[..., ::2][..., :n_c].copy()
            coarse = coarse[..., :n_c]
            if stop_every > 0:  # compare each drive over the samples it computed
                for r in range(R):
                    fine[r, :, (n_done[r] + 1) // 2 :] = 0.0
                    coarse[r, :, (n_done[r] + 1) // 2 :] = 0.0
            estimate = step_doubling_error(fine, coarse, order)
            method = f"step doubling (h = {h:.6g} s against 2h)"
        except StepTooLargeError:
            estimate, method = np.full(R, np.nan), "none: the step 2h is unstable"
        meta["error_estimate_rel"] = estimate
        meta["error_estimate_method"] = method
        meta["wall_s"] = time.perf_counter() - t_wall
    return SimResult(
        time_s=np.arange(n_samples) / sample_rate_Hz,
        velocity=vel,
        displacement=disp,
        drive=drv,
        cylinders=(rec + 1).astype(np.int32),
        meta=meta,
    )
