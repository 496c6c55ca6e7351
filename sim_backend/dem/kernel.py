"""Compiled (numba) time stepping of a batch of chain trajectories.

State of one trajectory: for every cylinder i (oriented so that the actuator is on the left of
index 0) the modal coordinates ``q[i, k]``, ``p[i, k]`` of its free (J+1)-DOF block
(primary mass + J resonators; mode 0 is the rigid translation), mass-normalised so that the
block's kinetic energy is ``sum p^2 / 2`` and its spring energy ``sum w_k^2 q^2 / 2``.

One step of length h is a symmetric splitting ``D(a_0 h) K(b_0 h) D(a_1 h) ... K(b_{m-1} h)
D(a_m h)``: ``D`` is the exact (damped) linear flow of every block mode (a rotation), ``K`` a kick
by the contact forces on the primary masses (Hertz, tensionless, with a Hunt-Crossley dashpot
``F = beta d^1.5 (1 + chi d')``). The positions are fixed during a kick but the dashpots' velocities
are not: on a damped chain the kick's flow ``m0 v' = F(v)`` is integrated by the explicit
midpoint rule (two force sweeps; local error ``O((h c / m0)^3)``) or, with ``heun_kicks``, by
Heun's third-order rule (three sweeps, ``O((h c / m0)^4)``). The midpoint error adds up over a
step as ``sum_k b_k^3``, which is 0 for ``yoshida4``, ``suzuki4`` and ``yoshida6`` (their
triple-jump construction) but not for ``blanes-moan4``: there it is second order, small, and
visible below an error of about 1e-6 (steps under 1 us); Heun's rule removes it. The last drift
of a step and the first of the next are merged. The moving wall's
work is summed as ``sum_k b_k h dV/dt`` (extended phase space) so that ``H(end) - H(0) - W``
measures the integrator's energy error when the damping is off.

Trajectories are processed in chunks of ``W`` lanes (same orientation, ``W`` a multiple of 4),
four lanes to a SIMD vector (:mod:`sim_backend.dem.simd`): every operation below acts on four
trajectories at once, and the per-lane arithmetic is the same whatever the chunk, so a drive's
result does not depend on the batch around it. One kick costs two passes (three with Heun
kicks): one over the cylinders (16, 8 or 4 lanes at a time: each coefficient read once for as
many vectors) applies the previous kick to the momenta, drifts every mode and sums the primary
displacement ``u`` in registers (from a shift per cylinder that holds the rest overlaps, so that
an overlap is one subtraction); one along the contacts, carrying the neighbours' values in
registers, gives the Hertz forces, the forces at the start velocities and, one contact behind,
the stage velocities and the forces there (one loop without branches per case: undamped,
midpoint, Heun, the last two once for each source of ``u'``; the chain's ends outside it). The
primary velocity ``u'``, which only the contact dashpots read, is summed where they read it, in
the second pass, for blocks of 4 modes (the benchmark chain's: the default chain has 4 modes and
no dashpot), in the first pass otherwise: the first pass is bound by its multiply-adds, the
second by its square roots. Lanes whose bursts differ only by their amplitude compute the
burst's shape once a kick (:func:`_burst_leads`), and no drive is evaluated outside every
lane's drive window.

The chunks are independent: :func:`run_batch` hands them to ``numba.get_num_threads()`` threads
that each call the compiled :func:`run_chunks` (serial, without the GIL) on the next chunk not
taken. Not numba's ``parallel=`` and ``prange``: numba compiles a parallel loop's body as a
function of its own and links it, with all it calls, into three more libraries (the gufunc
wrapper, the parallel wrapper, the caller), each optimised by LLVM and turned into machine code
again, and its parallel passes walk the body's IR besides; the kernel's first-use compile took
20-26 s so (docs/performance.md, section 3). In the compiled chunk loop the helpers numba inlines
take numbers and vectors, or the arrays the loop already holds (``_mode_drift``,
``_velocity4``, ``_burst_shape``); :func:`_record`, which took arrays numba reference-counted
around every call, is a function of its own; the drives are read by row index
(:func:`drive_value`), not as row views.

Steps split at the drives' breakpoints (``split_steps`` = 1, :mod:`sim_backend.dem.split_steps`):
an analytic burst's start and end, where a moving wall's velocity jumps and the actuator
contact's dashpot force with it, are known before the run. A step that holds one strictly inside
is done as sub-steps of the same scheme between them (drift coefficients computed for their
lengths, the last drift of one merged with the first of the next, the wall's work summed over
their kicks), each evaluating the drive by the formula of its own side of the breakpoint;
without this a jump between two kicks leaves an O(h) error that depends on where it falls
(docs/performance.md, section 3). The samples that hold such a step are listed per chunk
before the run, so a sample costs one comparison more; such a sample is run once per group of
lanes with the same breakpoints in it, from its start state, each lane keeping its own group's
pass, so a drive's result still does not depend on the batch around it, and a run without a
breakpoint inside a step gives the same bits as with ``split_steps`` = 0. Table waveforms
(linear interpolation: the slope jumps at every table sample) are not split.

Optional (default off, results bit-for-bit unchanged): ``record_flags`` skips the recording of
unrequested quantities (bit 0 velocity, 1 displacement, 2 drive; an unrequested output array is
never touched, so it may have zero length), and ``stop_every > 0`` checks every ``stop_every``
samples whether the energy left in each lane, ``H(t) - H_static``, is at most ``stop_fraction``
times the input work with every lane's drive finished; when it is for every lane of a chunk, that
chunk stops recording (``energy[r, 3]`` = samples recorded, ``energy[r, 4]`` = energy left (J),
when ``energy`` has 5 columns).
"""

from __future__ import annotations

import itertools
import math
import threading

import numba
import numpy as np
from numpy.typing import NDArray

from sim_backend.dem.kernel_cache import install_cache_locator
from sim_backend.dem.simd import Vec4, vbcast, vfma, vload, vmax, vsplat, vsqrt, vstore
from sim_backend.dem.split_steps import (
    find_breakpoints,
    keep_lanes,
    lane_groups,
    load_state,
    pass_drifts,
    pass_entries,
    save_state,
    split_samples,
    split_schedule,
)

install_cache_locator()  # compiled code goes to the user's cache folder, not next to the sources

__all__ = [
    "NUMERICS_VERSION",
    "drift_coefficients",
    "drive_value",
    "run_batch",
    "run_chunks",
]

#: changes whenever the kernel's arithmetic changes its results beyond rounding; cached converged
#: references (``sim_backend.dem.converged``) are keyed by it
NUMERICS_VERSION = "4: overlaps from shifted displacements, fused dashpot and stage"


def drift_coefficients(
    omega: NDArray[np.float64], zeta: NDArray[np.float64], h: float
) -> NDArray[np.float64]:
    """Exact flow of ``q'' + 2 zeta w q' + w^2 q = 0`` over ``h`` s: ``[..., 4]`` = (a, b, c, d)
    with ``q1 = a q0 + b p0``, ``p1 = c q0 + d p0``. ``omega`` (rad/s), ``zeta`` same shape;
    ``h`` may be negative (backward substeps of high-order compositions)."""
    out = np.empty((*omega.shape, 4))
    w = omega
    rigid = w <= 0.0
    z = np.where(rigid, 0.0, zeta)
    wd = w * np.sqrt(1.0 - z**2)
    wd_safe = np.where(rigid, 1.0, wd)
    e = np.exp(-z * w * h)
    c = np.cos(wd * h)
    s = np.sin(wd * h)
    out[..., 0] = np.where(rigid, 1.0, e * (c + z * w / wd_safe * s))
    out[..., 1] = np.where(rigid, h, e * s / wd_safe)
    out[..., 2] = np.where(rigid, 0.0, -e * w**2 / wd_safe * s)
    out[..., 3] = np.where(rigid, 1.0, e * (c - z * w / wd_safe * s))
    return out


@numba.njit(inline="always")
def _burst(tau: float, prm: NDArray[np.float64], r: int) -> tuple[float, float]:
    """(value, d value/dt) of the analytic burst of drive ``r`` (:func:`drive_value`) at
    ``tau`` s after its start, by its formula whether or not ``0 < tau < T``."""
    env, cs, slope = _burst_shape(tau, prm, r)
    return _burst_scaled(prm[r, 0], env, cs, slope)


@numba.njit(inline="always")
def _burst_scaled(amp: float, env: float, cs: float, slope: float) -> tuple[float, float]:
    """(value, d value/dt) of a burst of amplitude ``amp`` from its shape (:func:`_burst_shape`):
    the kernel's lanes that share a shape take their drive by it too, so the bits are
    :func:`drive_value`'s by construction."""
    return amp * env * cs, amp * slope


@numba.njit(inline="always")
def _burst_shape(tau: float, prm: NDArray[np.float64], r: int) -> tuple[float, float, float]:
    """What :func:`_burst` takes from drive ``r``'s shape, not from its amplitude: the envelope,
    the carrier's cosine and the slope per unit amplitude, ``(env, cos, d(env cos)/dt)`` (1, 1,
    1/s). A lane whose burst differs from another's by its amplitude alone reuses them
    (``run_chunks``: one exp, cos and sin a kick for a whole amplitude sweep)."""
    sig = prm[r, 3]
    x = tau - prm[r, 4]
    g = math.exp(-x * x / (2.0 * sig * sig))
    norm = 1.0 / (1.0 - prm[r, 5])
    env = (g - prm[r, 5]) * norm
    denv = -x / (sig * sig) * g * norm
    om = 2.0 * math.pi * prm[r, 1]
    cs = math.cos(om * x)
    sn = math.sin(om * x)
    return env, cs, denv * cs - env * om * sn


@numba.njit(inline="always")
def _drive_on(
    t: float, src: int, amp: float, delay: float, T: float, rate: float, n_table: int
) -> bool:
    """Whether :func:`drive_value` computes the drive at ``t`` (s) rather than returning 0: a
    nonzero amplitude, and ``t`` inside the burst's window or the table. Numbers only: a helper
    that numba inlines is cheap only without arrays (it reference-counts those at every call),
    and the kernel asks this for every lane and sample."""
    if amp == 0.0:
        return False
    tau = t - delay
    if src == 0:
        return not (tau <= 0.0 or tau >= T)
    xs = tau * rate
    return not (xs < 0.0 or xs >= n_table - 1)


@numba.njit(cache=True)
def drive_value(
    t: float,
    r: int,
    src: NDArray[np.int64],
    prm: NDArray[np.float64],
    tables: NDArray[np.float64],
    n_table: NDArray[np.int64],
) -> tuple[float, float]:
    """(value, d value/dt) of drive ``r`` at trigger time ``t`` (s); ``src``, ``prm``,
    ``tables``, ``n_table`` are :func:`run_chunks`' (every drive: a row of each is not taken
    as an array of its own, whose reference counting cost the kernel 6 %).

    ``src[r]`` 0: analytic Gaussian burst, ``prm[r]`` = (amp, f, T, sigma, t0, e_end, delay, -);
    ``src[r]`` 1: table of ``n_table[r]`` samples at rate ``prm[r, 7]`` played from ``delay``,
    linear.
    """
    amp = prm[r, 0]
    if not _drive_on(t, src[r], amp, prm[r, 6], prm[r, 2], prm[r, 7], n_table[r]):
        return 0.0, 0.0
    tau = t - prm[r, 6]
    if src[r] == 0:
        return _burst(tau, prm, r)
    rate = prm[r, 7]
    xs = tau * rate
    j = int(xs)
    fr = xs - j
    a = tables[r, j]
    b = tables[r, j + 1]
    return amp * (a + fr * (b - a)), amp * (b - a) * rate


@numba.njit(cache=True)
def drive_piece(
    t: float,
    side: float,
    r: int,
    src: NDArray[np.int64],
    prm: NDArray[np.float64],
    tables: NDArray[np.float64],
    n_table: NDArray[np.int64],
) -> tuple[float, float]:
    """:func:`drive_value` at ``t`` (s) by the formula that holds at ``side`` (s), a time between
    the same two breakpoints (:mod:`sim_backend.dem.split_steps`): an analytic burst's value
    and slope on that side of its start and end, also at the breakpoint itself."""
    if src[r] != 0 or prm[r, 0] == 0.0:
        return drive_value(t, r, src, prm, tables, n_table)
    if not _drive_on(side, 0, prm[r, 0], prm[r, 6], prm[r, 2], prm[r, 7], n_table[r]):
        return 0.0, 0.0  # the burst is off on that side
    return _burst(t - prm[r, 6], prm, r)


@numba.njit(cache=True)
def _lane_energy(
    q: NDArray[np.float64],  # [N, K, W]
    p: NDArray[np.float64],  # [N, K, W]
    u: NDArray[np.float64],  # [N, W] scratch: primary displacements of lane b on return
    b: int,
    phi: NDArray[np.float64],  # [N, K]
    omega: NDArray[np.float64],  # [N, K]
    dv: float,  # drive value (m or N)
    kind: int,  # 0 moving wall, 1 force
    beta: float,
    d0: NDArray[np.float64],  # [N+1] rest overlap of each contact (m), oriented
    f0: float,
    far_wall: int,
) -> float:
    """Hamiltonian (J) of lane ``b``: block energies, Hertz contact energies and preload terms."""
    N = q.shape[0]
    K = q.shape[1]
    hh = 0.0
    for i in range(N):
        uu = 0.0
        for k in range(K):
            hh += 0.5 * p[i, k, b] ** 2 + 0.5 * omega[i, k] ** 2 * q[i, k, b] ** 2
            uu += phi[i, k] * q[i, k, b]
        u[i, b] = uu
    if kind == 0:
        d = d0[0] + dv - u[0, b]
        if d > 0.0:
            hh += 0.4 * beta * d * d * math.sqrt(d)
    else:
        hh -= (f0 + dv) * u[0, b]
    for i in range(N - 1):
        d = d0[i + 1] + u[i, b] - u[i + 1, b]
        if d > 0.0:
            hh += 0.4 * beta * d * d * math.sqrt(d)
    if far_wall == 1:
        d = d0[N] + u[N - 1, b]
        if d > 0.0:
            hh += 0.4 * beta * d * d * math.sqrt(d)
    else:
        hh += f0 * u[N - 1, b]
    return hh


@numba.njit(cache=True)
def _burst_leads(
    lanes: NDArray[np.int64], src: NDArray[np.int64], prm: NDArray[np.float64]
) -> NDArray[np.int64]:
    """[W] per lane of a chunk (``lanes``: trajectory of each, -1: padding), the earlier lane
    whose analytic burst is the same but for its amplitude (``prm[r, 1:7]`` equal, both
    amplitudes nonzero), else -1. ``run_chunks`` computes the burst's shape (:func:`_burst_shape`:
    an exp, a cos and a sin) once a kick for such lanes, each lane multiplying by its own
    amplitude as :func:`_burst` does: the same bits, one shape a kick for an amplitude sweep's
    chunk instead of one a lane."""
    W = lanes.size
    lead = np.full(W, -1, dtype=np.int64)
    for b in range(W):
        r = lanes[b]
        if r < 0 or src[r] != 0 or prm[r, 0] == 0.0:
            continue
        for a in range(b):
            ra = lanes[a]
            if ra < 0 or src[ra] != 0 or prm[ra, 0] == 0.0 or lead[a] >= 0:
                continue
            same = True
            for c in range(1, 7):
                if prm[ra, c] != prm[r, c]:
                    same = False
            if same:
                lead[b] = a
                break
    return lead


@numba.njit(cache=True)
def _drive_end(src: int, prm: NDArray[np.float64], n_table: int) -> float:
    """Trigger time (s) after which a drive of :func:`drive_value` is zero."""
    if src == 0:
        return float(prm[6] + prm[2])
    return float(prm[6] + (n_table - 1) / prm[7])


#: samples recorded into a chunk's buffer before they are copied to the output arrays: each
#: lane's run of samples of one cylinder is then 512 B of the output (8 cache lines). The buffer
#: holds REC_BLOCK x C x W doubles per recorded quantity (127 kB for 31 cylinders and 8 lanes,
#: 254 kB for 16);
#: 16 measured 2-3 % slower on the sweep of ``benchmarks/dem_sweep.py``
REC_BLOCK = 64


@numba.njit(inline="always")
def _primary(x: NDArray[np.float64], phi: NDArray[np.float64], i: int, W: int, g: int) -> Vec4:
    """Primary-mass displacement (``x = q``) or velocity (``x = p``) of cylinder ``i``, lanes
    ``g .. g+3``: ``sum_k phi[i, k] x[i, k]``."""
    K = phi.shape[1]
    acc = vsplat(0.0)
    for k in range(K):
        acc = vfma(vsplat(phi[i, k]), vload(x, (i * K + k) * W + g), acc)
    return acc


@numba.njit(inline="always")
def _velocity4(p: NDArray[np.float64], phi: NDArray[np.float64], i: int, W: int, g: int) -> Vec4:
    """:func:`_primary` of ``x = p`` for a block of 4 modes, unrolled: ``phi`` is ``[N, 4]``
    flattened. Pass 2 reads the contacts' velocities by it, so that pass 1, bound by its
    multiply-adds, leaves them to pass 2, bound by its square roots (same operations, same
    order, same bits)."""
    b = i * 4
    acc = vfma(vbcast(phi, b), vload(p, b * W + g), vsplat(0.0))
    acc = vfma(vbcast(phi, b + 1), vload(p, (b + 1) * W + g), acc)
    acc = vfma(vbcast(phi, b + 2), vload(p, (b + 2) * W + g), acc)
    return vfma(vbcast(phi, b + 3), vload(p, (b + 3) * W + g), acc)


@numba.njit(cache=True)
def _record(
    buf: NDArray[np.float64],  # [REC_BLOCK, C, W] flat
    x: NDArray[np.float64],  # [N K W] flat: q or p
    phi: NDArray[np.float64],  # [N, K]
    rec: NDArray[np.int64],  # [C] the cylinders recorded
    slot: int,
    W: int,
) -> None:
    """``buf[slot, c]`` = the primary-mass displacement (``x = q``) or velocity (``x = p``) of
    cylinder ``rec[c]``, every lane (a function of its own: inlined into the sample loop, its
    array arguments were reference-counted at every cylinder and lane group)."""
    C = rec.size
    for c in range(C):
        for g in range(0, W, 4):
            vstore(buf, (slot * C + c) * W + g, _primary(x, phi, rec[c], W, g))


@numba.njit(cache=True)
def _copy_out(
    buf: NDArray[np.float64],  # [REC_BLOCK, C, W] flat
    out: NDArray[np.float64],  # [R, C, S]
    lanes: NDArray[np.int64],  # [W] trajectory of each lane (-1: padding)
    s0: int,
    n: int,
    sign: float,
) -> None:
    """``out[r, c, s0 + j] = sign buf[j, c, b]`` for the first ``n`` buffered samples of every
    lane ``b`` (trajectory ``r``); nothing when the quantity is not recorded (empty buffer)."""
    W = lanes.size
    C = out.shape[1]
    if buf.size == 0:
        return
    for b in range(W):
        r = lanes[b]
        if r < 0:
            continue
        for c in range(C):
            for j in range(n):
                out[r, c, s0 + j] = sign * buf[(j * C + c) * W + b]


@numba.njit(inline="always")
def _mode_coefficients(
    co: NDArray[np.float64],  # [drift kinds, N, K, 4] drift coefficients
    phi: NDArray[np.float64],  # [N, K]
    dk: int,
    i: int,
    k: int,
) -> tuple[Vec4, Vec4, Vec4, Vec4, Vec4]:
    """Mode ``k`` of cylinder ``i``'s drift of kind ``dk`` in every lane: the 2x2 drift
    ``c0 .. c3`` and its primary component ``phi`` (:func:`_mode_drift`'s ``f``)."""
    return (
        vsplat(co[dk, i, k, 0]),
        vsplat(co[dk, i, k, 1]),
        vsplat(co[dk, i, k, 2]),
        vsplat(co[dk, i, k, 3]),
        vsplat(phi[i, k]),
    )


@numba.njit(inline="always")
def _mode_drift(
    q: NDArray[np.float64],  # [N K W] flat
    p: NDArray[np.float64],
    j: int,  # index of the mode's first lane in q and p
    c0: Vec4,
    c1: Vec4,
    c2: Vec4,
    c3: Vec4,
    f: Vec4,  # phi0 of the mode (1/sqrt(kg))
    kick: Vec4,  # kick length x force on the primary mass (N s)
) -> tuple[Vec4, Vec4]:
    """One mode of four lanes: the pending kick ``p += f kick``, then the drift ``(q, p) <- [[c0,
    c1], [c2, c3]] (q, p)`` (each row one product and one fused multiply-add); stores and returns
    the new ``(q, p)``."""
    q0 = vload(q, j)
    p0 = vfma(f, kick, vload(p, j))
    q1 = vfma(c0, q0, c1 * p0)
    p1 = vfma(c2, q0, c3 * p0)
    vstore(q, j, q1)
    vstore(p, j, p1)
    return q1, p1


@numba.njit(inline="always")
def _hertz(d: Vec4, beta: float) -> Vec4:
    """Tensionless Hertz force ``beta [d]_+^1.5`` (N) of four overlaps ``d`` (m)."""
    d = vmax(d, vsplat(0.0))
    return beta * d * vsqrt(d)


@numba.njit(inline="always")
def _dashpot(fh: Vec4, chi: Vec4, rel_vel: Vec4) -> Vec4:
    """Hunt-Crossley contact force ``[fh (1 + chi d')]_+`` (N); ``rel_vel`` = d' (m/s). The
    factor is one fused multiply-add: a shorter chain of dependent operations per contact."""
    return vmax(fh * vfma(chi, rel_vel, vsplat(1.0)), vsplat(0.0))


@numba.njit(inline="always")
def _stage(
    v: Vec4, f_left: Vec4, f_right: Vec4, va_left: Vec4, fh_left: Vec4, chi_left: Vec4, c: Vec4
) -> tuple[Vec4, Vec4]:
    """A damped kick's first stage at a cylinder of start velocity ``v`` (m/s) between contacts
    with forces ``f_left``, ``f_right`` (N): its stage velocity ``va = v + c (f_left - f_right)``
    (``c`` = stage length / primary mass, s/kg), and the left contact's force at the stage
    velocities, ``va_left`` of its left cylinder (Hertz force ``fh_left``, factor ``chi_left``)."""
    va = vfma(c, f_left - f_right, v)
    return va, _dashpot(fh_left, chi_left, va_left - va)


@numba.njit(inline="always")
def _contact(
    chi: NDArray[np.float64],  # [N+1] Hunt-Crossley factors (s/m)
    cs1: NDArray[np.float64],  # [N] first stage velocity step per force (m/s/N)
    j: int,
    beta: float,
    u_prev: Vec4,
    v_prev: Vec4,
    g_prev: Vec4,
    f_prev: Vec4,
    va_pp: Vec4,
    u1: Vec4,
    v1: Vec4,
) -> tuple[Vec4, Vec4, Vec4, Vec4]:
    """A damped kick at contact ``j`` (between cylinders j-1 and j of displacements ``u_prev``,
    ``u1`` (m) and start velocities ``v_prev``, ``v1`` (m/s)): its Hertz force ``gj`` and its
    force ``fj`` at the start velocities (N), and one contact behind, cylinder j-1's stage
    velocity ``va`` and contact j-1's force ``k2`` at the stage velocities (its Hertz force
    ``g_prev``, its force ``f_prev``; cylinder j-2's stage velocity ``va_pp``)."""
    gj = _hertz(u_prev - u1, beta)
    fj = _dashpot(gj, vbcast(chi, j), v_prev - v1)
    va, k2 = _stage(v_prev, f_prev, fj, va_pp, g_prev, vbcast(chi, j - 1), vbcast(cs1, j - 1))
    return gj, fj, va, k2


@numba.njit(inline="always")
def _heun_keep(
    fh: NDArray[np.float64],  # [N+1, W] flat
    k1: NDArray[np.float64],
    vs: NDArray[np.float64],  # [N, W] flat
    cs2: NDArray[np.float64],  # [N] second stage velocity step per force (m/s/N)
    j: int,
    W: int,
    g: int,
    gj: Vec4,
    fj: Vec4,
    dk2: Vec4,
    v_pp: Vec4,
) -> None:
    """Heun's kick at contact ``j``: keeps its Hertz force and its force at the start velocities
    for pass 3, and cylinder j-2's second stage velocity ``v_pp + cs2 dk2`` (``dk2``: the net
    stage force on it, N)."""
    vstore(fh, j * W + g, gj)
    vstore(k1, j * W + g, fj)
    vstore(vs, (j - 2) * W + g, vfma(vbcast(cs2, j - 2), dk2, v_pp))


@numba.njit(inline="always")
def _actuator_force(
    fh: Vec4, chi: float, wall: Vec4, drive_vel: Vec4, v: Vec4, drive_force: Vec4
) -> Vec4:
    """Force (N) of the actuator contact on the first cylinder, velocity ``v`` (m/s): the moving
    wall's Hertz force ``fh`` with its dashpot (``wall`` = 1 on those lanes, else 0 and ``fh`` = 0),
    plus ``drive_force`` (the preload and drive on force-driven lanes, else 0)."""
    return _dashpot(fh, vsplat(chi), wall * (drive_vel - v)) + drive_force


@numba.njit(inline="always")
def _far_end_hertz(u_last: Vec4, far_rest: float, beta: float, far_wall: int) -> Vec4:
    """Hertz force (N) of the far-end contact: a wall at rest against the last cylinder of
    displacement ``u_last`` (m, summed from its shift: the overlap is ``far_rest + u_last``), or
    none on a free end."""
    if far_wall == 1:
        return _hertz(far_rest + u_last, beta)
    return vsplat(0.0)


@numba.njit(inline="always")
def _far_end_force(fh: Vec4, chi: float, v: Vec4, far_wall: int, f0: float) -> Vec4:
    """Force (N) of the far-end contact on the last cylinder, velocity ``v`` (m/s): a wall at rest
    (Hertz force ``fh`` with its dashpot) or, on a free end, the preload ``f0``."""
    if far_wall == 1:
        return _dashpot(fh, vsplat(chi), v)
    return vsplat(f0)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def run_chunks(
    first: int,  # the chunks first .. stop - 1 of lane_traj
    stop: int,
    phi0: NDArray[np.float64],  # [2, N, K] primary component of mass-normalised block modes
    omega: NDArray[np.float64],  # [2, N, K] block mode angular frequencies
    drift: NDArray[np.float64],  # [2, nd, N, K, 4] drift coefficients per drift kind
    chi: NDArray[np.float64],  # [2, N+1] Hunt-Crossley factors c/F0 (s/m) per contact
    inv_m0: NDArray[np.float64],  # [2, N] 1 / primary mass = sum_k phi0^2
    lane_traj: NDArray[np.int64],  # [nchunks, W] trajectory index of each lane (-1: padding)
    chunk_orient: NDArray[np.int64],  # [nchunks] 0 = as built (ltr), 1 = reversed (rtl)
    dkind: NDArray[np.int64],  # [R] 0 = moving Hertz wall, 1 = force
    src: NDArray[np.int64],  # [R] 0 = analytic burst, 1 = table
    prm: NDArray[np.float64],  # [R, 8]
    tables: NDArray[np.float64],  # [R, L]
    n_table: NDArray[np.int64],  # [R]
    kick_b: NDArray[np.float64],  # [m] kick weights
    drift_a: NDArray[np.float64],  # [m + 1] drift weights
    drift_seq: NDArray[np.int64],  # [m + 1] drift kind of each drift
    drift_merge: int,  # drift kind of (last + first) merged between steps
    h: float,
    n_sub: int,
    n_samples: int,
    beta: float,
    rest: NDArray[np.float64],  # [2, N+1] rest overlap of each contact (m): delta0 - gap
    f0: float,
    far_wall: int,
    rec_idx: NDArray[np.int64],  # [2, C] oriented indices to record
    vel: NDArray[np.float64],  # [R, C, S] out, m/s, positive from cylinder #1 towards #N
    disp: NDArray[np.float64],  # [R, C, S] out, m, same sign
    drv: NDArray[np.float64],  # [R, S] out
    energy: NDArray[np.float64],  # [R, 3], [R, 5] or [R, 6] out: H(0), H(end), W
    # (, samples, E left (, total momentum at the end, oriented))
    zeta: NDArray[np.float64],  # [2, N, K] damping ratio of each block mode (split steps' drifts)
    record_flags: int = 7,  # bit 0 velocity, bit 1 displacement, bit 2 drive
    stop_every: int = 0,  # > 0: check the energy left every stop_every samples
    stop_fraction: float = 0.0,  # stop once energy left <= stop_fraction * input work
    heun_kicks: int = 0,  # 1: damped kicks by Heun's third-order rule, 0: explicit midpoint
    split_steps: int = 1,  # 1: steps split at the bursts' start and end (module docstring)
) -> None:
    """The chunks ``first .. stop - 1`` of ``lane_traj`` (:func:`run_batch` runs them all, on
    threads); numba's ``error_model="numpy"``, as for the parallel loop's body it was."""
    W = lane_traj.shape[1]
    N = phi0.shape[1]
    K = phi0.shape[2]
    C = rec_idx.shape[1]
    m = kick_b.shape[0]
    damped = False
    for j in range(chi.shape[1]):
        if chi[0, j] > 0.0:
            damped = True
    # every contact rests at delta0 except gaps, which the chain file allows only with F0 = 0
    delta0 = max(rest[0].max(), 0.0)
    u0_static = 0.4 * beta * delta0 * delta0 * math.sqrt(delta0)
    rec_vel = (record_flags & 1) != 0
    rec_disp = (record_flags & 2) != 0
    rec_drv = (record_flags & 4) != 0
    n_contacts = N - 1 + far_wall
    heun = heun_kicks == 1
    first_stage = 1.0 / 3.0 if heun else 0.5  # first stage of a damped kick, in kick lengths
    # damped (a contact dashpot), the primary velocities u' are summed in pass 1 (into ud) or,
    # for blocks of 4 modes (the benchmark chain's), where pass 2 reads them (_velocity4): pass 1
    # is bound by its multiply-adds, pass 2 by its square roots (docs/performance.md, section 3)
    vel4 = damped and K == 4
    sum_vel = damped and not vel4
    # pass 1 drifts 16 lanes at a time (four vectors for each coefficient read) where the
    # chunk allows and it sums no u', else eight (two), else four
    quads = W % 16 == 0 and not sum_vel
    pairs = W % 8 == 0
    lane_step = 16 if quads else 8 if pairs else 4
    # one sample = n_sub steps = n_sub m kicks, each after a drift (the last drift of a step
    # merged with the first of the next), then a last drift
    n_kicks = n_sub * m
    kick_drift = np.empty(n_kicks + 1, dtype=np.int64)  # drift kind before each kick, and last
    kick_dt = np.empty(n_kicks + 1)  # length of that drift (s)
    kick_h = np.zeros(n_kicks + 1)  # length of the kick (s); 0 after the last drift
    for step in range(n_sub):
        for stage in range(m):
            kk = step * m + stage
            kick_h[kk] = kick_b[stage] * h
            if stage == 0 and step > 0:
                kick_drift[kk] = drift_merge
                kick_dt[kk] = float(drift_a[m] + drift_a[0]) * h
            else:
                kick_drift[kk] = drift_seq[stage]
                kick_dt[kk] = float(drift_a[stage]) * h
    kick_drift[n_kicks] = drift_seq[m]
    kick_dt[n_kicks] = float(drift_a[m]) * h
    kick_side = np.full(n_kicks + 1, math.nan)  # no breakpoint in the sample's steps
    kick_flag = np.zeros(n_kicks + 1, dtype=np.int64)  # bit 0: a pass's first drift, 1: its last
    kick_flag[0] = 1
    kick_flag[n_kicks] = 2
    period = h * n_sub
    nd = drift.shape[1]
    for ch in range(first, stop):
        o = chunk_orient[ch]
        sign = -1.0 if o == 1 else 1.0  # recorded along the chain's axis (#1 towards #N)
        lanes = lane_traj[ch]
        q = np.zeros(N * K * W)  # [N, K, W]
        p = np.zeros(N * K * W)
        u = np.zeros(N * W)  # [N, W] primary displacement
        ud = np.zeros(N * W)  # primary velocity, summed in pass 1 (sum_vel; else zeros)
        force = np.zeros(N * W)  # contact force on each primary mass (N)
        fh = np.zeros((N + 1) * W)  # [N+1, W] Hertz force of each contact (N)
        k1 = np.zeros((N + 1) * W)  # contact force at the kick's start velocities (N)
        vs = np.zeros(N * W)  # stage velocities of the kick (m/s)
        scratch = np.zeros((N, W))
        dval = np.zeros(W)
        b_on = np.zeros(W, dtype=np.bool_)  # a burst lane's drive on at this kick, its shape:
        b_env = np.zeros(W)  # envelope, carrier cosine, slope per unit amplitude (_burst_shape)
        b_cos = np.zeros(W)
        b_slope = np.zeros(W)
        ddot = np.zeros(W)
        wall = np.zeros(W)  # 1.0 where the lane's drive is a moving wall
        fdrv = np.zeros(W)  # 1.0 where the lane's drive is a force
        work = np.zeros(W)
        buf_vel = np.zeros(REC_BLOCK * C * W if rec_vel else 0)  # [REC_BLOCK, C, W]
        buf_disp = np.zeros(REC_BLOCK * C * W if rec_disp else 0)
        phi = phi0[o]
        phif = phi.reshape(N * K)  # [N K] flat, for _velocity4
        d0 = rest[o]
        rec = rec_idx[o]
        x0 = chi[o]
        im0 = inv_m0[o]
        # pass 1 sums each primary displacement from shift[i] (m), so that contact j's overlap
        # d0[j] + u[j-1] - u[j] is one subtraction in pass 2: shift[j] = shift[j-1] - d0[j]
        shift = np.zeros(N)
        for i in range(1, N):
            shift[i] = shift[i - 1] - d0[i]
        far_rest = d0[N] - shift[N - 1]  # the far end's overlap is far_rest + u[N-1] shifted
        cs1 = np.zeros(N)  # per kick: first stage velocity step per force (m/s/N), hk/m0 x c
        cs2 = np.zeros(N)  # and Heun's second, hk/m0 x 2/3
        # steps split at the drives' breakpoints: the samples that hold one, per lane
        bp_n = np.zeros(W, dtype=np.int64)
        bp_smp = np.zeros((W, 2), dtype=np.int64)
        bp_st = np.zeros((W, 2), dtype=np.int64)
        bp_y = np.zeros((W, 2))
        if split_steps == 1:
            find_breakpoints(lanes, src, prm, period, h, n_sub, n_samples, bp_n, bp_smp, bp_st,
                             bp_y)  # fmt: skip
        split_at, n_pass_max = split_samples(bp_n, bp_smp, bp_st, bp_y)
        # the drift kinds, then room for the split steps' drifts
        co = np.empty((nd + n_pass_max * pass_drifts(m), N, K, 4))
        for a in range(nd):  # element loops: no slice assignment's shape check in the body
            for i in range(N):
                for k in range(K):
                    for c in range(4):
                        co[a, i, k, c] = drift[o, a, i, k, c]
        n_split = split_at.size
        next_split = split_at[0] if n_split > 0 else -1
        i_split = 0
        n_sched = n_pass_max * pass_entries(n_kicks, m)
        sk_drift = np.zeros(n_sched, dtype=np.int64)  # a split sample's schedule
        sk_dt = np.zeros(n_sched)
        sk_h = np.zeros(n_sched)
        sk_side = np.zeros(n_sched)
        sk_flag = np.zeros(n_sched, dtype=np.int64)
        n_state = (2 * N * K * W + N * W + W) if n_split > 0 else 0
        keep = np.zeros(n_state)  # the chunk's state at the split sample's start
        res = np.zeros(n_state)  # and at its end, each lane from its own pass
        group = np.zeros(W, dtype=np.int64)
        t_start = 0.0
        t_end = 0.0
        ps = 0
        q3 = q.reshape((N, K, W))
        p3 = p.reshape((N, K, W))
        # the chunk's drives are all zero outside [t_on, t_off) (s)
        t_on = math.inf
        t_off = -math.inf
        for b in range(W):
            r = lanes[b]
            if r >= 0:
                wall[b] = 1.0 if dkind[r] == 0 else 0.0
                fdrv[b] = 1.0 - wall[b]
                if prm[r, 0] != 0.0:
                    t_on = min(t_on, prm[r, 6])
                    t_off = max(t_off, _drive_end(src[r], prm[r], n_table[r]))
            else:
                wall[b] = 1.0
        # a lane whose burst is another's but for its amplitude takes that lane's burst shape
        lead = _burst_leads(lanes, src, prm)
        t = 0.0
        drives_zero = False  # dval and ddot hold zeros for every lane
        n_rec = n_samples
        for s in range(n_samples):
            # record the state at t = s / rate (into the block buffers, copied out every
            # REC_BLOCK samples)
            slot = s % REC_BLOCK
            if rec_vel:
                _record(buf_vel, p, phi, rec, slot, W)
            if rec_disp:
                _record(buf_disp, q, phi, rec, slot, W)
            if slot == REC_BLOCK - 1 or s == n_samples - 1:
                _copy_out(buf_vel, vel, lanes, s - slot, slot + 1, sign)
                _copy_out(buf_disp, disp, lanes, s - slot, slot + 1, sign)
            if rec_drv:
                for b in range(W):
                    r = lanes[b]
                    if r >= 0:
                        on = _drive_on(t, src[r], prm[r, 0], prm[r, 6], prm[r, 2], prm[r, 7],
                                       n_table[r])  # fmt: skip
                        drv[r, s] = drive_value(t, r, src, prm, tables, n_table)[0] if on else 0.0
            if s == n_samples - 1:
                break
            if stop_every > 0 and s > 0 and s % stop_every == 0:
                # early stop: every lane's drive over and its energy left negligible
                quiet = True
                for b in range(W):
                    r = lanes[b]
                    if r < 0 or not quiet:
                        continue
                    if prm[r, 0] != 0.0 and t <= _drive_end(src[r], prm[r], n_table[r]):
                        quiet = False
                        continue
                    h_static = (n_contacts + (1 if dkind[r] == 0 else 0)) * u0_static
                    left = (
                        _lane_energy(q3, p3, scratch, b, phi, omega[o], 0.0, dkind[r], beta, d0,
                                     f0, far_wall)
                        - h_static
                    )  # fmt: skip
                    if left > stop_fraction * work[b]:
                        quiet = False
                if quiet:
                    n_rec = s + 1
                    _copy_out(buf_vel, vel, lanes, s - slot, slot + 1, sign)
                    _copy_out(buf_disp, disp, lanes, s - slot, slot + 1, sign)
                    break
            kd, kdt, kh, kside, kflag = kick_drift, kick_dt, kick_h, kick_side, kick_flag
            n_entries = n_kicks + 1
            split = s == next_split
            if split:  # one pass per group of lanes with the same breakpoints in this sample
                n_groups = lane_groups(s, bp_n, bp_smp, bp_st, bp_y, group)
                n_entries = split_schedule(
                    s, group, n_groups, bp_n, bp_smp, bp_st, bp_y, period, h, n_sub, kick_b,
                    drift_a, kick_drift, kick_dt, kick_h, omega[o], zeta[o], co, nd, sk_drift,
                    sk_dt, sk_h, sk_side, sk_flag,
                )  # fmt: skip
                kd, kdt, kh, kside, kflag = sk_drift, sk_dt, sk_h, sk_side, sk_flag
                save_state(keep, q, p, force, work)
                t_start = t
                t_end = t  # the clock as a whole sample advances it
                for kk in range(n_kicks + 1):
                    t_end += kick_dt[kk]
                ps = 0
            hk_prev = 0.0  # length (s) of the kick whose forces wait to be applied to p
            for kk in range(n_entries):
                if kk > 0 and (kflag[kk] & 1) != 0:  # the next pass, from the sample's start
                    keep_lanes(res, q, p, force, work, group, ps)
                    ps += 1
                    load_state(keep, q, p, force, work)
                    t = t_start
                    hk_prev = 0.0
                dk = kd[kk]
                t += kdt[kk]
                # ---- pass 1, per cylinder: the pending kick, the drift, then u and (sum_vel) u'
                # (lane groups outside: 7 % less time for the kernel than cylinders outside;
                # without u' undamped, 4 % less for a sweep of the default chain; 16 lanes at a
                # time, 4-7 % less than 8: docs/performance.md, section 3)
                for g in range(0, W, lane_step):
                    for i in range(N):
                        ja = i * W + g
                        if quads:
                            fa = hk_prev * vload(force, ja)
                            fb = hk_prev * vload(force, ja + 4)
                            fc = hk_prev * vload(force, ja + 8)
                            fe = hk_prev * vload(force, ja + 12)
                            ua = vsplat(shift[i])
                            ub, uc, ue = ua, ua, ua
                            for k in range(K):
                                c0, c1, c2, c3, f = _mode_coefficients(co, phi, dk, i, k)
                                jm = (i * K + k) * W + g
                                qa, _ = _mode_drift(q, p, jm, c0, c1, c2, c3, f, fa)
                                qb, _ = _mode_drift(q, p, jm + 4, c0, c1, c2, c3, f, fb)
                                qc, _ = _mode_drift(q, p, jm + 8, c0, c1, c2, c3, f, fc)
                                qe, _ = _mode_drift(q, p, jm + 12, c0, c1, c2, c3, f, fe)
                                ua = vfma(f, qa, ua)
                                ub = vfma(f, qb, ub)
                                uc = vfma(f, qc, uc)
                                ue = vfma(f, qe, ue)
                            vstore(u, ja, ua)
                            vstore(u, ja + 4, ub)
                            vstore(u, ja + 8, uc)
                            vstore(u, ja + 12, ue)
                            continue
                        fa = hk_prev * vload(force, ja)
                        fb = hk_prev * vload(force, ja + 4) if pairs else fa
                        ua = vsplat(shift[i])
                        va = vsplat(0.0)
                        ub = ua
                        vb = vsplat(0.0)
                        for k in range(K):
                            c0, c1, c2, c3, f = _mode_coefficients(co, phi, dk, i, k)
                            jm = (i * K + k) * W + g
                            qa, pa = _mode_drift(q, p, jm, c0, c1, c2, c3, f, fa)
                            ua = vfma(f, qa, ua)
                            if sum_vel:  # u' is read only by the contact dashpots
                                va = vfma(f, pa, va)
                            if pairs:
                                qb, pb = _mode_drift(q, p, jm + 4, c0, c1, c2, c3, f, fb)
                                ub = vfma(f, qb, ub)
                                if sum_vel:
                                    vb = vfma(f, pb, vb)
                        vstore(u, ja, ua)
                        if sum_vel:
                            vstore(ud, ja, va)
                        if pairs:
                            vstore(u, ja + 4, ub)
                            if sum_vel:
                                vstore(ud, ja + 4, vb)
                hk = kh[kk]
                hk_prev = hk
                if (kflag[kk] & 2) != 0:
                    continue
                if damped:
                    for i in range(N):
                        cs1[i] = hk * im0[i] * first_stage
                if damped and heun:
                    for i in range(N):
                        cs2[i] = hk * im0[i] * (2.0 / 3.0)
                # ---- the drives at t (in a split step: on the sub-step's side of its breakpoints)
                # (outside every lane's drive window, all zero: written once, not every kick)
                side = kside[kk]
                if side == side or t_on <= t < t_off:
                    drives_zero = False
                    for b in range(W):
                        r = lanes[b]
                        if r >= 0 and side == side:
                            dval[b], ddot[b] = drive_piece(t, side, r, src, prm, tables, n_table)
                        elif r >= 0 and t_on <= t < t_off:
                            a = lead[b]  # the lane whose burst shape this lane's drive takes
                            if a < 0 and src[r] == 0:  # a burst of its own: its shape at t
                                b_on[b] = _drive_on(t, 0, prm[r, 0], prm[r, 6], prm[r, 2],
                                                    prm[r, 7], n_table[r])  # fmt: skip
                                if b_on[b]:
                                    b_env[b], b_cos[b], b_slope[b] = _burst_shape(
                                        t - prm[r, 6], prm, r
                                    )
                                a = b
                            if a < 0:  # a table
                                dval[b], ddot[b] = drive_value(t, r, src, prm, tables, n_table)
                            elif b_on[a]:
                                dval[b], ddot[b] = _burst_scaled(
                                    prm[r, 0], b_env[a], b_cos[a], b_slope[a]
                                )
                            else:
                                dval[b] = 0.0
                                ddot[b] = 0.0
                        else:
                            dval[b] = 0.0
                            ddot[b] = 0.0
                elif not drives_zero:
                    for b in range(W):
                        dval[b] = 0.0
                        ddot[b] = 0.0
                    drives_zero = True
                # ---- pass 2, along the contacts (0: actuator, j: between cylinders j-1 and j,
                # N: far end), carrying the neighbours' values: Hertz forces and the contact
                # forces at the start velocities, k1; undamped, the forces on the cylinders.
                # Damped, the kick's flow m0 v' = F(v): one contact behind, the stage velocities
                # va = v + c h k1 / m0 and the forces k2 at those, c = 1/2 (explicit midpoint:
                # k2 acts on the cylinders) or 1/3 (Heun's third-order rule: two contacts behind,
                # the second stage vb = v + (2h/3) k2 / m0 into vs, with fh and k1 kept for
                # pass 3, which gives the forces k3 at vb and the kick's (k1 + 3 k3) / 4).
                # Each case has a loop over the contacts between cylinders of its own, without a
                # branch inside (first contact and far end before and after it): 25 instructions
                # a contact against 58 with the cases as branches in one loop, 10 cycles a 4-lane
                # vector against 16 on Zen 3 (docs/performance.md, section 3, "Pass 2 without
                # branches"); the vel4 loops, which sum u' too, 9.9 cycles on Zen 5. Its
                # coefficients by vbcast: no negative-index check per read.
                zero = vsplat(0.0)
                for g in range(0, W, 4):
                    wl = vload(wall, g)
                    fd = vload(fdrv, g)
                    dv = vload(dval, g)
                    dd = vload(ddot, g)
                    drive_force = fd * (f0 + dv)
                    u_prev = vload(u, g)
                    v_prev = _velocity4(p, phif, 0, W, g) if vel4 else vload(ud, g)
                    g_prev = _hertz(wl * (d0[0] + dv - u_prev), beta)
                    vstore(work, g, vload(work, g) + hk * dd * (wl * g_prev - fd * u_prev))
                    f_prev = _actuator_force(g_prev, x0[0], wl, dd, v_prev, drive_force)
                    if heun:
                        vstore(fh, g, g_prev)
                        vstore(k1, g, f_prev)
                    if not damped:  # every chi is 0: a contact's force is its Hertz force
                        for j in range(1, N):
                            u1 = vload(u, j * W + g)
                            fj = _hertz(u_prev - u1, beta)
                            vstore(force, (j - 1) * W + g, f_prev - fj)
                            u_prev = u1
                            f_prev = fj
                        gj = _far_end_hertz(u_prev, far_rest, beta, far_wall)
                        fj = _far_end_force(gj, x0[N], zero, far_wall, f0)  # chi = 0: no d'
                        vstore(force, (N - 1) * W + g, f_prev - fj)
                        continue
                    # contact 1 (the far end if N = 1), and the actuator's k2 at cylinder 0's
                    # stage velocity
                    if N > 1:
                        u1 = vload(u, W + g)
                        v1 = _velocity4(p, phif, 1, W, g) if vel4 else vload(ud, W + g)
                        gj = _hertz(u_prev - u1, beta)
                        fj = _dashpot(gj, vsplat(x0[1]), v_prev - v1)
                    else:
                        u1 = zero
                        v1 = zero
                        gj = _far_end_hertz(u_prev, far_rest, beta, far_wall)
                        fj = _far_end_force(gj, x0[N], v_prev, far_wall, f0)
                    if heun:
                        vstore(fh, W + g, gj)
                        vstore(k1, W + g, fj)
                    va_pp = vfma(vsplat(cs1[0]), f_prev - fj, v_prev)  # cylinder j-2's va
                    k2_pp = _actuator_force(g_prev, x0[0], wl, dd, va_pp, drive_force)
                    v_pp = v_prev  # cylinder j-2's start velocity
                    u_prev, v_prev, g_prev, f_prev = u1, v1, gj, fj
                    # one loop per case, the primary velocities read from p (vel4) or ud
                    # one loop per case and source of u' (p summed by _velocity4, or ud): a
                    # select between the two inside one loop cost 2.5 %
                    if heun and vel4:  # the second stage velocities into vs; fh, k1 for pass 3
                        for j in range(2, N):
                            u1, v1 = vload(u, j * W + g), _velocity4(p, phif, j, W, g)
                            gj, fj, va, k2 = _contact(x0, cs1, j, beta, u_prev, v_prev, g_prev,
                                                      f_prev, va_pp, u1, v1)  # fmt: skip
                            _heun_keep(fh, k1, vs, cs2, j, W, g, gj, fj, k2_pp - k2, v_pp)
                            v_pp, va_pp, k2_pp = v_prev, va, k2
                            u_prev, v_prev, g_prev, f_prev = u1, v1, gj, fj
                    elif heun:
                        for j in range(2, N):
                            u1, v1 = vload(u, j * W + g), vload(ud, j * W + g)
                            gj, fj, va, k2 = _contact(x0, cs1, j, beta, u_prev, v_prev, g_prev,
                                                      f_prev, va_pp, u1, v1)  # fmt: skip
                            _heun_keep(fh, k1, vs, cs2, j, W, g, gj, fj, k2_pp - k2, v_pp)
                            v_pp, va_pp, k2_pp = v_prev, va, k2
                            u_prev, v_prev, g_prev, f_prev = u1, v1, gj, fj
                    elif vel4:  # the midpoint: k2 acts on the cylinders
                        for j in range(2, N):
                            u1, v1 = vload(u, j * W + g), _velocity4(p, phif, j, W, g)
                            gj, fj, va_pp, k2 = _contact(x0, cs1, j, beta, u_prev, v_prev, g_prev,
                                                         f_prev, va_pp, u1, v1)  # fmt: skip
                            vstore(force, (j - 2) * W + g, k2_pp - k2)
                            u_prev, v_prev, g_prev, f_prev, k2_pp = u1, v1, gj, fj, k2
                    else:
                        for j in range(2, N):
                            u1, v1 = vload(u, j * W + g), vload(ud, j * W + g)
                            gj, fj, va_pp, k2 = _contact(x0, cs1, j, beta, u_prev, v_prev, g_prev,
                                                         f_prev, va_pp, u1, v1)  # fmt: skip
                            vstore(force, (j - 2) * W + g, k2_pp - k2)
                            u_prev, v_prev, g_prev, f_prev, k2_pp = u1, v1, gj, fj, k2
                    if N > 1:  # the far end: cylinder N-1's stage velocity, contact N-1's k2
                        gj = _far_end_hertz(u_prev, far_rest, beta, far_wall)
                        fj = _far_end_force(gj, x0[N], v_prev, far_wall, f0)
                        if heun:
                            vstore(fh, N * W + g, gj)
                            vstore(k1, N * W + g, fj)
                        va, k2 = _stage(
                            v_prev, f_prev, fj, va_pp, g_prev, vsplat(x0[N - 1]), vsplat(cs1[N - 1])
                        )
                        if heun:
                            vstore(vs, (N - 2) * W + g, vfma(vsplat(cs2[N - 2]), k2_pp - k2, v_pp))
                        else:
                            vstore(force, (N - 2) * W + g, k2_pp - k2)
                        v_pp, va_pp, k2_pp, g_prev = v_prev, va, k2, gj
                    # the far-end contact's k2; the last cylinder's force or second stage
                    k2 = _far_end_force(g_prev, x0[N], va_pp, far_wall, f0)
                    if heun:
                        vstore(vs, (N - 1) * W + g, vfma(vsplat(cs2[N - 1]), k2_pp - k2, v_pp))
                    else:
                        vstore(force, (N - 1) * W + g, k2_pp - k2)
                if not (damped and heun):
                    continue
                # ---- pass 3 (damped): the forces k3 at the second stage velocities, and the
                # kick's forces (k1 + 3 k3) / 4 on the cylinders
                for g in range(0, W, 4):
                    v_prev = vload(vs, g)
                    d_force = vload(fdrv, g) * (f0 + vload(dval, g))
                    wl = vload(wall, g)
                    dd = vload(ddot, g)
                    f_prev = _actuator_force(vload(fh, g), x0[0], wl, dd, v_prev, d_force)
                    f_prev = 0.25 * (vload(k1, g) + 3.0 * f_prev)
                    for j in range(1, N + 1):
                        if j < N:
                            v1 = vload(vs, j * W + g)
                            fj = _dashpot(vload(fh, j * W + g), vbcast(x0, j), v_prev - v1)
                        else:
                            v1 = vsplat(0.0)
                            fj = _far_end_force(vload(fh, j * W + g), x0[N], v_prev, far_wall, f0)
                        fj = 0.25 * (vload(k1, j * W + g) + 3.0 * fj)
                        vstore(force, (j - 1) * W + g, f_prev - fj)
                        v_prev = v1
                        f_prev = fj
            if split:  # every lane's state from the pass of its own breakpoints
                keep_lanes(res, q, p, force, work, group, ps)
                load_state(res, q, p, force, work)
                t = t_end
                i_split += 1
                next_split = split_at[i_split] if i_split < n_split else -1
        # ---- energy at the end (and at the start: the static state)
        for b in range(W):
            r = lanes[b]
            if r < 0:
                continue
            dv_end = drive_value(t, r, src, prm, tables, n_table)[0]
            hh = _lane_energy(q3, p3, scratch, b, phi, omega[o], dv_end, dkind[r], beta, d0, f0,
                              far_wall)  # fmt: skip
            energy[r, 0] = (n_contacts + (1 if dkind[r] == 0 else 0)) * u0_static
            energy[r, 1] = hh
            energy[r, 2] = work[b]
            if energy.shape[1] >= 5:
                energy[r, 3] = n_rec
                energy[r, 4] = hh - energy[r, 0]
            if energy.shape[1] >= 6:  # total momentum (kg m/s), oriented: sum_i sqrt(m_i) p_i0
                mom = 0.0
                for i in range(N):
                    mom += p3[i, 0, b] / phi[i, 0]
                energy[r, 5] = mom


def run_batch(
    phi0: NDArray[np.float64],
    omega: NDArray[np.float64],
    drift: NDArray[np.float64],
    chi: NDArray[np.float64],
    inv_m0: NDArray[np.float64],
    lane_traj: NDArray[np.int64],
    chunk_orient: NDArray[np.int64],
    dkind: NDArray[np.int64],
    src: NDArray[np.int64],
    prm: NDArray[np.float64],
    tables: NDArray[np.float64],
    n_table: NDArray[np.int64],
    kick_b: NDArray[np.float64],
    drift_a: NDArray[np.float64],
    drift_seq: NDArray[np.int64],
    drift_merge: int,
    h: float,
    n_sub: int,
    n_samples: int,
    beta: float,
    rest: NDArray[np.float64],
    f0: float,
    far_wall: int,
    rec_idx: NDArray[np.int64],
    vel: NDArray[np.float64],
    disp: NDArray[np.float64],
    drv: NDArray[np.float64],
    energy: NDArray[np.float64],
    zeta: NDArray[np.float64],
    record_flags: int = 7,
    stop_every: int = 0,
    stop_fraction: float = 0.0,
    heun_kicks: int = 0,
    split_steps: int = 1,
) -> None:
    """Every chunk of ``lane_traj``: :func:`run_chunks` (the same arguments after ``first`` and
    ``stop``) on ``numba.get_num_threads()`` threads at most, this one among them, each taking
    the next chunk not yet taken (module docstring). The chunks are independent (each writes
    only its own trajectories' outputs): the result does not depend on the threads."""
    args = (
        phi0, omega, drift, chi, inv_m0, lane_traj, chunk_orient, dkind, src, prm, tables,
        n_table, kick_b, drift_a, drift_seq, drift_merge, h, n_sub, n_samples, beta, rest, f0,
        far_wall, rec_idx, vel, disp, drv, energy, zeta, record_flags, stop_every, stop_fraction,
        heun_kicks, split_steps,
    )  # fmt: skip
    n_chunks = lane_traj.shape[0]
    n_threads = min(numba.get_num_threads(), n_chunks)
    if n_threads <= 1:
        run_chunks(0, n_chunks, *args)
        return
    taken = itertools.count()  # next() is atomic under the GIL
    errors: list[BaseException] = []

    def work() -> None:
        try:
            while (ch := next(taken)) < n_chunks:
                run_chunks(ch, ch + 1, *args)
        except BaseException as exc:  # re-raised in the calling thread
            errors.append(exc)

    others = [threading.Thread(target=work, name=f"dem-kernel-{j}") for j in range(1, n_threads)]
    for thread in others:
        thread.start()
    work()
    for thread in others:
        thread.join()
    if errors:
        raise errors[0]
