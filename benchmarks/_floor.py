"""Floors of the compiled DEM kernel (``sim_backend.dem.kernel.run_batch``): what its operations
would cost at this machine's measured rates.

:func:`kernel_ops` counts the kernel's vector operations per step and trajectory from its loops,
by pass and by class: ``fma`` (fused multiply-add), ``other`` (add, subtract, multiply, max: the
vector operations that are not multiply-adds) and ``sqrt``. Not counted: loads, stores,
broadcasts, the scalar products of coefficients (a few per contact) and the drives (scalar, only
while a drive is on). ``tests/dem/test_kernel_ops.py`` checks the counts against the kernel's own
source run with counting stand-ins for its vectors. From them:

- :func:`flops_per_step`: floating-point operations (a multiply-add counts 2, anything else 1);
  over :func:`peak_flops` (independent multiply-adds on every thread) the *flops floor*;
- :func:`instruction_floor`: per pass, the larger of the square-root unit's time (the square
  roots at the measured rate of ``vsqrtpd``) and the arithmetic ports' time (multiply-adds at
  the measured multiply-add rate plus the other operations at theirs: one set of ports for
  both, as on Intel cores since Skylake; :func:`instruction_rates` measures a mix of the two
  to check that on the host), summed over the passes: the *instruction floor*. It differs from
  the flops floor in that an add, a multiply or a max costs as much as a multiply-add, and a
  square root as much as the unit that computes it.

Rates are measured by small numba kernels on the same four-lane vectors as the kernel
(:mod:`sim_backend.dem.simd`), on every thread; a rate is in lane operations per second (one
four-lane instruction = 4).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numba
import numpy as np

from sim_backend.dem.kernel_cache import install_cache_locator
from sim_backend.dem.simd import vfma, vlane, vmax, vsplat, vsqrt

install_cache_locator()  # before the decorators below: compiled code to the user's cache folder

#: operation classes of :func:`kernel_ops`
OP_CLASSES = ("fma", "other", "sqrt")


def kernel_ops(
    n_cyl: int,
    n_block: int,
    n_kicks: int,
    n_sub: int,
    dashpot: bool,
    n_recorded: int,
    heun_kicks: bool = False,
    far_wall: bool = True,
) -> dict[str, dict[str, float]]:
    """Vector operations of ``run_batch`` per step and trajectory (one four-lane instruction
    counts once per lane group, i.e. per trajectory), by pass and class (:data:`OP_CLASSES`).

    N cylinders, K = J + 1 block modes, m kicks a step, ``n_sub`` steps a sample, ``dashpot``: a
    contact dashpot on (the kernel's damped kicks), C cylinders whose velocity is recorded.
    Executed operations, the unneeded ones included (u, and u' where pass 1 sums it, after a
    sample's last drift).

    - ``pass1``, after every drift (m per step and one per sample): per cylinder the kick length
      x force (1 other); per mode the pending kick (1 fma), the 2x2 drift (2 fma, 2 other) and
      the mode's share of u (1 fma) and, with a dashpot and a block of other than 4 modes, of u'
      (1 fma). With a dashpot and 4 modes (:func:`velocity_in_pass2`) pass 2 sums u' instead,
      every kick: K fma per cylinder.
    - ``pass2``, every kick. A contact's force at a velocity, ``[fh (1 + chi d')]_+``, is one
      multiply-add and 2 other (the factor, the product, the max). The actuator (lane masks,
      drive force, the Hertz force with its overlap, the wall's work, the force at the start
      velocities): 19 other, 1 fma, 1 sqrt. Between cylinders: the overlap (1: the
      displacements are summed from shifts that hold the rest overlaps), the Hertz force (2
      multiplies and a max, 1 sqrt); at a far wall: overlap 1, Hertz 3 and 1 sqrt, force at the
      start velocities 2 and 1 fma (a free end: nothing). No dashpot: a contact's force is its
      Hertz force; the force on each cylinder (1 each). Dashpot: between cylinders the force at
      the start velocities (relative velocity 1, force 2 and 1 fma), per cylinder the stage
      velocity (1 and 1 fma), per contact the force at the stage velocities (actuator 5 and 1
      fma, between cylinders 3 and 1 fma, far wall 2 and 1 fma), per cylinder the force on it
      (midpoint, 1) or its second stage velocity (Heun, 1 and 1 fma).
    - ``pass3``, every kick with Heun kicks: the actuator 10 and 1 fma (drive force 2, force 5
      and 1 fma, ``(k1 + 3 k3) / 4`` 3), per contact between cylinders the force (3 and 1 fma),
      the average (3) and the force on the cylinder (1); the far end 6 and 1 fma (a free end 4).
    - ``record``, every sample: per recorded cylinder the velocity ``sum_k phi_k p_k`` (K fma).
    """
    N, K = n_cyl, n_block
    w = 1 if far_wall else 0
    drifts = n_kicks + 1.0 / n_sub
    vel2 = velocity_in_pass2(dashpot, K)
    fma1 = (5 if dashpot and not vel2 else 4) * N * K * drifts
    out = {"pass1": {"fma": fma1, "other": (2 * N * K + N) * drifts, "sqrt": 0.0}}
    other = 19 + 4 * (N - 1) + 6 * w
    fma = 1 + w
    if not dashpot:
        other += N
    else:
        other += 3 * (N - 1) + N + (5 + 3 * (N - 1) + 2 * w) + N
        fma += (N - 1) + N + (1 + (N - 1) + w) + (N if heun_kicks else 0)
        if vel2:
            fma += N * K
    out["pass2"] = {"fma": float(fma * n_kicks), "other": float(other * n_kicks),
                    "sqrt": float((N + w) * n_kicks)}  # fmt: skip
    if dashpot and heun_kicks:
        pass3 = 10 + 7 * (N - 1) + 2 * w + 4
        out["pass3"] = {"fma": float((N + w) * n_kicks), "other": float(pass3 * n_kicks),
                        "sqrt": 0.0}  # fmt: skip
    out["record"] = {"fma": K * n_recorded / n_sub, "other": 0.0, "sqrt": 0.0}
    return out


def flops_per_step(
    n_cyl: int,
    n_block: int,
    n_kicks: int,
    n_sub: int,
    dashpot: bool,
    n_recorded: int,
    heun_kicks: bool = False,
    far_wall: bool = True,
) -> float:
    """Floating-point operations of one step of one trajectory that the result needs: the
    operations of :func:`kernel_ops` (a multiply-add counts 2, a sqrt, max, add, subtract or
    multiply 1) less u and u' (with a dashpot, when pass 1 sums it) after a sample's last drift
    (2 N K flops per sample each), which the kernel computes and does not use: the same count
    wherever u' is summed."""
    ops = kernel_ops(n_cyl, n_block, n_kicks, n_sub, dashpot, n_recorded, heun_kicks, far_wall)
    total = sum(2.0 * c["fma"] + c["other"] + c["sqrt"] for c in ops.values())
    return total - unneeded_flops(n_cyl, n_block, n_sub, dashpot)


def unneeded_flops(n_cyl: int, n_block: int, n_sub: int, dashpot: bool) -> float:
    """Flops a step of pass 1 in :func:`kernel_ops` that the result does not need: u and, with a
    dashpot summed in pass 1, u' after a sample's last drift (2 N K flops a sample each)."""
    in_pass1 = dashpot and not velocity_in_pass2(dashpot, n_block)
    return (4.0 if in_pass1 else 2.0) * n_cyl * n_block / n_sub


def velocity_in_pass2(dashpot: bool, n_block: int) -> bool:
    """Whether ``run_chunks`` sums the primary velocities u' in pass 2, every kick, where the
    contacts read them (a dashpot and blocks of 4 modes: its ``vel4``), not in pass 1."""
    return dashpot and n_block == 4


# --- measured rates -----------------------------------------------------------------------


@numba.njit(cache=True)
def _sqrt_lanes(n_iter: int, t: int) -> float:
    """8 independent square-root chains ``a = sqrt(a) + c`` per thread (one add per root)."""
    c = vsplat(1.7)
    a0, a1, a2, a3 = vsplat(2.1 + t), vsplat(2.2), vsplat(2.3), vsplat(2.4)
    a4, a5, a6, a7 = vsplat(2.5), vsplat(2.6), vsplat(2.7), vsplat(2.8)
    for _ in range(n_iter):
        a0, a1, a2, a3 = vsqrt(a0) + c, vsqrt(a1) + c, vsqrt(a2) + c, vsqrt(a3) + c
        a4, a5, a6, a7 = vsqrt(a4) + c, vsqrt(a5) + c, vsqrt(a6) + c, vsqrt(a7) + c
    return vlane(a0 + a1 + a2 + a3 + a4 + a5 + a6 + a7, 0)


@numba.njit(parallel=True, cache=True)
def _sqrt_kernel(n_iter: int, n_par: int) -> np.ndarray:  # type: ignore[type-arg]
    out = np.zeros(n_par)
    for t in numba.prange(n_par):
        out[t] = _sqrt_lanes(n_iter, t)
    return out


@numba.njit(cache=True)
def _other_lanes(n_iter: int, t: int) -> float:
    """20 operations per iteration and thread: 8 chains ``a = max(a, 0) + d`` (a max against 0
    is one instruction, as in the kernel; two variables' maxnum is three) and 4 multiplies."""
    z = vsplat(0.0)
    d = vsplat(1e-9)
    c = vsplat(1.0 - 1e-10)
    a0, a1, a2, a3 = vsplat(1.0 + t), vsplat(2.0), vsplat(3.0), vsplat(4.0)
    a4, a5, a6, a7 = vsplat(5.0), vsplat(6.0), vsplat(7.0), vsplat(8.0)
    p0, p1, p2, p3 = vsplat(1.0), vsplat(2.0), vsplat(3.0), vsplat(4.0)
    for _ in range(n_iter):
        a0, a1, a2, a3 = vmax(a0, z) + d, vmax(a1, z) + d, vmax(a2, z) + d, vmax(a3, z) + d
        a4, a5, a6, a7 = vmax(a4, z) + d, vmax(a5, z) + d, vmax(a6, z) + d, vmax(a7, z) + d
        p0, p1, p2, p3 = p0 * c, p1 * c, p2 * c, p3 * c
    s = a0 + a1 + a2 + a3 + a4 + a5 + a6 + a7 + p0 + p1 + p2 + p3
    return vlane(s, 0)


@numba.njit(parallel=True, cache=True)
def _other_kernel(n_iter: int, n_par: int) -> np.ndarray:  # type: ignore[type-arg]
    out = np.zeros(n_par)
    for t in numba.prange(n_par):
        out[t] = _other_lanes(n_iter, t)
    return out


@numba.njit(cache=True)
def _fma_lanes(n_iter: int, t: int) -> float:
    """10 independent multiply-add chains per thread."""
    c = vsplat(0.999999)
    d = vsplat(1e-7)
    x0, x1, x2, x3, x4 = vsplat(1.0 + t), vsplat(1.1), vsplat(1.2), vsplat(1.3), vsplat(1.4)
    x5, x6, x7, x8, x9 = vsplat(1.5), vsplat(1.6), vsplat(1.7), vsplat(1.8), vsplat(1.9)
    for _ in range(n_iter):
        x0 = vfma(x0, c, d)
        x1 = vfma(x1, c, d)
        x2 = vfma(x2, c, d)
        x3 = vfma(x3, c, d)
        x4 = vfma(x4, c, d)
        x5 = vfma(x5, c, d)
        x6 = vfma(x6, c, d)
        x7 = vfma(x7, c, d)
        x8 = vfma(x8, c, d)
        x9 = vfma(x9, c, d)
    return vlane(x0 + x1 + x2 + x3 + x4 + x5 + x6 + x7 + x8 + x9, 0)


@numba.njit(parallel=True, cache=True)
def _vfma_kernel(n_iter: int, n_par: int) -> np.ndarray:  # type: ignore[type-arg]
    out = np.zeros(n_par)
    for t in numba.prange(n_par):
        out[t] = _fma_lanes(n_iter, t)
    return out


@numba.njit(cache=True)
def _mixed_lanes(n_iter: int, t: int) -> float:
    """8 multiply-adds and 8 other operations (4 max + add chains) per iteration and thread,
    in the 16 vector registers (12 chains, 4 constants)."""
    c = vsplat(0.999999)
    d = vsplat(1e-7)
    z = vsplat(0.0)
    e = vsplat(1e-9)
    x0, x1, x2, x3 = vsplat(1.0 + t), vsplat(1.1), vsplat(1.2), vsplat(1.3)
    x4, x5, x6, x7 = vsplat(1.5), vsplat(1.6), vsplat(1.7), vsplat(1.8)
    a0, a1, a2, a3 = vsplat(1.0), vsplat(2.0), vsplat(3.0), vsplat(4.0)
    for _ in range(n_iter):
        x0, x1, x2, x3 = vfma(x0, c, d), vfma(x1, c, d), vfma(x2, c, d), vfma(x3, c, d)
        x4, x5, x6, x7 = vfma(x4, c, d), vfma(x5, c, d), vfma(x6, c, d), vfma(x7, c, d)
        a0, a1, a2, a3 = vmax(a0, z) + e, vmax(a1, z) + e, vmax(a2, z) + e, vmax(a3, z) + e
    s = x0 + x1 + x2 + x3 + x4 + x5 + x6 + x7 + a0 + a1 + a2 + a3
    return vlane(s, 0)


@numba.njit(parallel=True, cache=True)
def _mixed_kernel(n_iter: int, n_par: int) -> np.ndarray:  # type: ignore[type-arg]
    out = np.zeros(n_par)
    for t in numba.prange(n_par):
        out[t] = _mixed_lanes(n_iter, t)
    return out


def _best_s(kernel: Any, n_iter: int, n_par: int, repeats: int) -> float:
    kernel(2, n_par)  # compiled (or loaded from the cache) before the timing
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        kernel(n_iter, n_par)
        best = min(best, time.perf_counter() - t0)
    return best


def peak_flops(repeats: int = 5, n_iter: int = 4_000_000) -> float:
    """Measured peak (flop/s) of independent multiply-adds on every numba thread, best of
    ``repeats``: the multiply-add rate kernel (:func:`_fma_lanes`, 10 chains of four-lane
    ``vfmadd`` held in registers), a multiply-add counting 2 flops. On the AMD host this is 16
    flops a cycle, the core's rated double-precision peak (two four-lane multiply-add pipes).

    It replaced a loop over a 64-double array (``fastmath``) whose vectors did not fit the
    registers and went to and from the stack: the stack's alignment being drawn per process, it
    read 20-59 Gflop/s from one process to the next on one core, its best above the rated 16
    flops a cycle (docs/performance.md, "The peak, measured again")."""
    n_par = numba.get_num_threads()
    return 2.0 * 10 * 4 * n_iter * n_par / _best_s(_vfma_kernel, n_iter, n_par, repeats)


def instruction_rates(repeats: int = 3, scale: float = 1.0) -> dict[str, float]:
    """Measured rates (lane operations/s, every numba thread, best of ``repeats``) of
    ``sqrt`` (``vsqrtpd``), ``other`` (add, max, multiply) and ``fma``; ``mixed_vs_sum``: the
    time of a 50/50 mix of multiply-adds and other operations over the time the two rates
    predict for it if they share one set of ports (about 1 when they do, about 0.5 when they
    are on separate ports). ``scale`` shortens the kernels (tests); each takes about 50 ms at 1."""
    n_par = numba.get_num_threads()
    lanes = 4.0 * n_par
    n_sqrt = max(1, int(2_000_000 * scale))
    n_other = max(1, int(20_000_000 * scale))
    n_fma = max(1, int(40_000_000 * scale))
    t_sqrt = _best_s(_sqrt_kernel, n_sqrt, n_par, repeats)
    t_other = _best_s(_other_kernel, n_other, n_par, repeats)
    t_fma = _best_s(_vfma_kernel, n_fma, n_par, repeats)
    n_mixed = n_fma // 2
    t_mixed = _best_s(_mixed_kernel, n_mixed, n_par, repeats)
    rates = {
        "sqrt": 8.0 * n_sqrt * lanes / t_sqrt,
        "other": 20.0 * n_other * lanes / t_other,
        "fma": 10.0 * n_fma * lanes / t_fma,
    }
    predicted = 8.0 * n_mixed * lanes * (1.0 / rates["fma"] + 1.0 / rates["other"])
    rates["mixed_vs_sum"] = t_mixed / predicted
    return rates


def instruction_floor(
    ops: dict[str, dict[str, float]], rates: dict[str, float], lane_steps: float
) -> dict[str, Any]:
    """The instruction floor (s) of ``lane_steps`` trajectory-steps of a kernel whose counts per
    step and trajectory are ``ops`` (:func:`kernel_ops`), at ``rates`` (:func:`instruction_rates`):
    per pass ``max(sqrt / rate_sqrt, fma / rate_fma + other / rate_other)``, summed. Returns
    ``total_s``, and per pass ``<pass>_s`` and ``<pass>_bound`` (``"sqrt"`` or ``"ports"``)."""
    out: dict[str, Any] = {}
    total = 0.0
    for name, c in ops.items():
        t_sqrt = c["sqrt"] / rates["sqrt"]
        t_ports = c["fma"] / rates["fma"] + c["other"] / rates["other"]
        t = max(t_sqrt, t_ports) * lane_steps
        out[f"{name}_s"] = t
        out[f"{name}_bound"] = "sqrt" if t_sqrt > t_ports else "ports"
        total += t
    out["total_s"] = total
    return out
