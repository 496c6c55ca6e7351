"""Compiled (numba) time stepping of a batch of chain trajectories.

State of one trajectory: for every cylinder i (oriented so that the actuator is on the left of
index 0) the modal coordinates ``q[i, k]``, ``p[i, k]`` of its free (J+1)-DOF block
(primary mass + J resonators; mode 0 is the rigid translation), mass-normalised so that the
block's kinetic energy is ``sum p^2 / 2`` and its spring energy ``sum w_k^2 q^2 / 2``.

One step of length h is a symmetric splitting ``D(a_0 h) K(b_0 h) D(a_1 h) ... K(b_{m-1} h)
D(a_m h)``: ``D`` is the exact (damped) linear flow of every block mode (a rotation), ``K`` a kick
by the contact forces on the primary masses (Hertz, tensionless, with a Hunt-Crossley dashpot
``F = beta d^1.5 (1 + chi d')`` whose velocity is taken at the explicit midpoint of the kick,
second order). The last drift of a step and the first of the next are merged. The moving wall's
work is summed as ``sum_k b_k h dV/dt`` (extended phase space) so that ``H(end) - H(0) - W``
measures the integrator's energy error when the damping is off.

Trajectories are processed in lanes of ``W`` (same orientation), the innermost loops running
over the lanes so that they vectorise.

Optional (default off, results bit-for-bit unchanged): ``record_flags`` skips the recording of
unrequested quantities (bit 0 velocity, 1 displacement, 2 drive; an unrequested output array is
never touched, so it may have zero length), and ``stop_every > 0`` checks every ``stop_every``
samples whether the energy left in each lane, ``H(t) - H_static``, is at most ``stop_fraction``
times the input work with every lane's drive finished; when it is for every lane of a chunk, that
chunk stops recording (``energy[r, 3]`` = samples recorded, ``energy[r, 4]`` = energy left (J),
when ``energy`` has 5 columns).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["drift_coefficients", "drive_value", "run_batch"]


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


@numba.njit(cache=True)
def drive_value(
    t: float, src: int, prm: NDArray[np.float64], table: NDArray[np.float64], n_table: int
) -> tuple[float, float]:
    """(value, d value/dt) of one drive at trigger time ``t`` (s).

    ``src`` 0: analytic Gaussian burst, ``prm`` = (amp, f, T, sigma, t0, e_end, delay, -);
    ``src`` 1: table of ``n_table`` samples at rate ``prm[7]`` played from ``delay``, linear.
    """
    amp = prm[0]
    if amp == 0.0:
        return 0.0, 0.0
    tau = t - prm[6]
    if src == 0:
        T = prm[2]
        if tau <= 0.0 or tau >= T:
            return 0.0, 0.0
        sig = prm[3]
        x = tau - prm[4]
        g = math.exp(-x * x / (2.0 * sig * sig))
        norm = 1.0 / (1.0 - prm[5])
        env = (g - prm[5]) * norm
        denv = -x / (sig * sig) * g * norm
        om = 2.0 * math.pi * prm[1]
        cs = math.cos(om * x)
        sn = math.sin(om * x)
        return amp * env * cs, amp * (denv * cs - env * om * sn)
    rate = prm[7]
    xs = tau * rate
    if xs < 0.0 or xs >= n_table - 1:
        return 0.0, 0.0
    j = int(xs)
    fr = xs - j
    a = table[j]
    b = table[j + 1]
    return amp * (a + fr * (b - a)), amp * (b - a) * rate


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


@numba.njit(cache=True, parallel=True)
def run_batch(
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
    vel: NDArray[np.float64],  # [R, C, S] out
    disp: NDArray[np.float64],  # [R, C, S] out
    drv: NDArray[np.float64],  # [R, S] out
    energy: NDArray[np.float64],  # [R, 3], [R, 5] or [R, 6] out: H(0), H(end), W
    # (, samples, E left (, total momentum at the end, oriented))
    record_flags: int = 7,  # bit 0 velocity, bit 1 displacement, bit 2 drive
    stop_every: int = 0,  # > 0: check the energy left every stop_every samples
    stop_fraction: float = 0.0,  # stop once energy left <= stop_fraction * input work
) -> None:
    n_chunks, W = lane_traj.shape
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
    for ch in numba.prange(n_chunks):
        o = chunk_orient[ch]
        lanes = lane_traj[ch]
        q = np.zeros((N, K, W))
        p = np.zeros((N, K, W))
        u = np.zeros((N, W))
        ud = np.zeros((N, W))
        force = np.zeros((N, W))
        gap = np.zeros((N + 1, W))
        fh = np.zeros((N + 1, W))
        fcon = np.zeros((N + 1, W))
        dval = np.zeros(W)
        ddot = np.zeros(W)
        wall = np.zeros(W)  # 1.0 where the lane's drive is a moving wall
        fdrv = np.zeros(W)  # 1.0 where the lane's drive is a force
        work = np.zeros(W)
        ru = np.zeros(W)
        rv = np.zeros(W)
        phi = phi0[o]
        d0 = rest[o]
        for b in range(W):
            r = lanes[b]
            if r >= 0:
                wall[b] = 1.0 if dkind[r] == 0 else 0.0
                fdrv[b] = 1.0 - wall[b]
            else:
                wall[b] = 1.0
        t = 0.0
        n_rec = n_samples
        for s in range(n_samples):
            # record the state at t = s / rate
            for c in range(C if (rec_vel or rec_disp) else 0):
                i = rec_idx[o, c]
                for b in range(W):
                    ru[b] = 0.0
                    rv[b] = 0.0
                for k in range(K):
                    f = phi[i, k]
                    for b in range(W):
                        ru[b] += f * q[i, k, b]
                        rv[b] += f * p[i, k, b]
                for b in range(W):
                    r = lanes[b]
                    if r >= 0:
                        if rec_disp:
                            disp[r, c, s] = ru[b]
                        if rec_vel:
                            vel[r, c, s] = rv[b]
            if rec_drv:
                for b in range(W):
                    r = lanes[b]
                    if r >= 0:
                        drv[r, s] = drive_value(t, src[r], prm[r], tables[r], n_table[r])[0]
            if s == n_samples - 1:
                break
            if stop_every > 0 and s > 0 and s % stop_every == 0:
                # early stop: every lane's drive over and its energy left negligible
                quiet = True
                for b in range(W):
                    r = lanes[b]
                    if r < 0 or not quiet:
                        continue
                    if src[r] == 0:
                        t_end = prm[r, 6] + prm[r, 2]
                    else:
                        t_end = prm[r, 6] + (n_table[r] - 1) / prm[r, 7]
                    if prm[r, 0] != 0.0 and t <= t_end:
                        quiet = False
                        continue
                    h_static = (n_contacts + (1 if dkind[r] == 0 else 0)) * u0_static
                    left = (
                        _lane_energy(q, p, u, b, phi, omega[o], 0.0, dkind[r], beta, d0, f0,
                                     far_wall)
                        - h_static
                    )  # fmt: skip
                    if left > stop_fraction * work[b]:
                        quiet = False
                if quiet:
                    n_rec = s + 1
                    break
            for step in range(n_sub):
                for stage in range(m + 1):
                    # ---- drift
                    if stage == 0:
                        dk = drift_seq[0] if step == 0 else -1
                        if step == 0:
                            t += float(drift_a[0]) * h
                    elif stage == m:
                        if step == n_sub - 1:
                            dk = drift_seq[m]
                            t += float(drift_a[m]) * h
                        else:
                            dk = drift_merge
                            t += float(drift_a[m] + drift_a[0]) * h
                    else:
                        dk = drift_seq[stage]
                        t += float(drift_a[stage]) * h
                    if dk >= 0:
                        co = drift[o, dk]
                        for i in range(N):
                            for k in range(K):
                                c0 = co[i, k, 0]
                                c1 = co[i, k, 1]
                                c2 = co[i, k, 2]
                                c3 = co[i, k, 3]
                                for b in range(W):
                                    q0 = q[i, k, b]
                                    p0 = p[i, k, b]
                                    q[i, k, b] = c0 * q0 + c1 * p0
                                    p[i, k, b] = c2 * q0 + c3 * p0
                    if stage == m:
                        break
                    # ---- kick
                    hk = kick_b[stage] * h
                    for i in range(N):
                        for b in range(W):
                            u[i, b] = 0.0
                            ud[i, b] = 0.0
                        for k in range(K):
                            f = phi[i, k]
                            for b in range(W):
                                u[i, b] += f * q[i, k, b]
                                ud[i, b] += f * p[i, k, b]
                    for b in range(W):
                        r = lanes[b]
                        if r >= 0:
                            dv, dd = drive_value(t, src[r], prm[r], tables[r], n_table[r])
                            dval[b] = dv
                            ddot[b] = dd
                    # conservative Hertz forces of every contact (0: left end, N: right end)
                    for b in range(W):
                        gap[0, b] = wall[b] * (d0[0] + dval[b] - u[0, b])
                        gap[N, b] = far_wall * (d0[N] + u[N - 1, b])
                    for j in range(1, N):
                        for b in range(W):
                            gap[j, b] = d0[j] + u[j - 1, b] - u[j, b]
                    for j in range(N + 1):
                        for b in range(W):
                            d = max(gap[j, b], 0.0)
                            fh[j, b] = beta * d * math.sqrt(d)
                    for b in range(W):
                        work[b] += hk * (wall[b] * fh[0, b] * ddot[b] - fdrv[b] * ddot[b] * u[0, b])
                    for sweep in range(2 if damped else 1):
                        if damped:
                            # Hunt-Crossley dashpots, velocities at the start (sweep 0) then at
                            # the explicit midpoint ud + (h/2) F / m0 (sweep 1)
                            x = chi[o, 0]
                            for b in range(W):
                                dv = wall[b] * (ddot[b] - ud[0, b])
                                fcon[0, b] = max(fh[0, b] * (1.0 + x * dv), 0.0)
                            x = chi[o, N]
                            for b in range(W):
                                fcon[N, b] = max(fh[N, b] * (1.0 + x * ud[N - 1, b]), 0.0)
                            for j in range(1, N):
                                x = chi[o, j]
                                for b in range(W):
                                    dv = ud[j - 1, b] - ud[j, b]
                                    fcon[j, b] = max(fh[j, b] * (1.0 + x * dv), 0.0)
                        else:
                            for j in range(N + 1):
                                for b in range(W):
                                    fcon[j, b] = fh[j, b]
                        for b in range(W):
                            fcon[0, b] += fdrv[b] * (f0 + dval[b])
                            if far_wall == 0:
                                fcon[N, b] = f0
                        for i in range(N):
                            for b in range(W):
                                force[i, b] = fcon[i, b] - fcon[i + 1, b]
                        if damped and sweep == 0:
                            for i in range(N):
                                x = 0.5 * hk * inv_m0[o, i]
                                for b in range(W):
                                    ud[i, b] += x * force[i, b]
                    for i in range(N):
                        for k in range(K):
                            f = hk * phi[i, k]
                            for b in range(W):
                                p[i, k, b] += f * force[i, b]
        # ---- energy at the end (and at the start: the static state)
        for b in range(W):
            r = lanes[b]
            if r < 0:
                continue
            dv = drive_value(t, src[r], prm[r], tables[r], n_table[r])[0]
            hh = _lane_energy(q, p, u, b, phi, omega[o], dv, dkind[r], beta, d0, f0, far_wall)
            energy[r, 0] = (n_contacts + (1 if dkind[r] == 0 else 0)) * u0_static
            energy[r, 1] = hh
            energy[r, 2] = work[b]
            if energy.shape[1] >= 5:
                energy[r, 3] = n_rec
                energy[r, 4] = hh - energy[r, 0]
            if energy.shape[1] >= 6:  # total momentum (kg m/s), oriented: sum_i sqrt(m_i) p_i0
                mom = 0.0
                for i in range(N):
                    mom += p[i, 0, b] / phi[i, 0]
                energy[r, 5] = mom
