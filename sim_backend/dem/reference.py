"""The same chain as plain NumPy: matrices of the linearised chain and the full nonlinear
right-hand side ``rhs(t, y)`` for ``scipy.integrate.solve_ivp`` (one trajectory), as
independent checks of the compiled integrators.

Coordinates (physical, oriented so that the drive is on the left of index 0): ``x`` = [u_0..u_{N-1},
v_00..v_0(J-1), v_10, ...] (primary displacements, then resonator displacements cylinder by
cylinder), ``y = [x, x']``. Results are oriented; flip index and sign for ``rtl`` drives.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import eigh

from sim_backend.dem.chain import Chain
from sim_backend.dem.drive import Drive
from sim_backend.dem.threads import one_blas_thread

__all__ = ["linear_matrices", "make_rhs"]


def _oriented(chain: Chain, direction: str) -> tuple[NDArray[np.float64], ...]:
    sl = slice(None) if direction == "ltr" else slice(None, None, -1)
    return chain.m0_kg[sl], chain.m_res_kg[sl], chain.k_res_N_per_m[sl]


def linear_matrices(
    chain: Chain, direction: str = "ltr", drive_kind: str = "displacement"
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Mass M, stiffness K (contacts linearised to ``chain.K_lin``), damping C and drive vector
    b of the oriented chain: ``M x'' + C x' + K x = b * drive(t)`` with drive in m (moving wall)
    or N (force). Shapes [D, D] and [D], D = N (J + 1). Damping: block-modal ratio of the
    resonators plus the contact dashpots (the linearised Hunt-Crossley ones)."""
    m0, mr, kr = _oriented(chain, direction)
    N, J = mr.shape
    D = N * (J + 1)
    M = np.zeros((D, D))
    K = np.zeros((D, D))
    C = np.zeros((D, D))
    res = lambda i, j: N + i * J + j  # noqa: E731
    for i in range(N):
        M[i, i] = m0[i]
        for j in range(J):
            a, b_ = i, res(i, j)
            M[b_, b_] = mr[i, j]
            K[a, a] += kr[i, j]
            K[b_, b_] += kr[i, j]
            K[a, b_] -= kr[i, j]
            K[b_, a] -= kr[i, j]
    dash = chain.contact_dashpot_Ns_per_m()
    rest = chain.rest_overlap_m
    if direction == "rtl":
        dash = dash[::-1]
        rest = rest[::-1]
    for jc in range(N + 1):
        left, right = jc - 1, jc
        # a contact open at rest (a gap) has no linear stiffness
        kc = (
            chain.K_lin
            if rest[jc] == chain.delta0_m
            else 1.5 * chain.beta_c * math.sqrt(max(float(rest[jc]), 0.0))
        )
        for mat, val in ((K, kc), (C, dash[jc])):
            if jc == 0:
                if drive_kind == "displacement":
                    mat[0, 0] += val
            elif jc == N:
                if chain.far_end == "wall":
                    mat[N - 1, N - 1] += val
            else:
                mat[left, left] += val
                mat[right, right] += val
                mat[left, right] -= val
                mat[right, left] -= val
    # block-modal damping of the resonators (the kernel's: ratio zeta on every flexible mode)
    zeta = chain.bending_damping_ratio
    if zeta > 0:
        for i in range(N):
            idx = [i] + [res(i, j) for j in range(J)]
            Mb = M[np.ix_(idx, idx)]
            Kb = np.zeros((J + 1, J + 1))
            Kb[0, 0] = kr[i].sum()
            Kb[0, 1:] = -kr[i]
            Kb[1:, 0] = -kr[i]
            Kb[1:, 1:] = np.diag(kr[i])
            with one_blas_thread():
                lam, phi = eigh(Kb, Mb)
            lam[0] = 0.0
            w = np.sqrt(np.maximum(lam, 0.0))
            C[np.ix_(idx, idx)] += Mb @ phi @ np.diag(2.0 * zeta * w) @ phi.T @ Mb
    bvec = np.zeros(D)
    bvec[0] = kc if drive_kind == "displacement" else 1.0
    return M, K, C, bvec


def make_rhs(
    chain: Chain, drive: Drive
) -> tuple[Callable[[float, NDArray[np.float64]], NDArray[np.float64]], NDArray[np.float64]]:
    """``(rhs, y0)`` of the full nonlinear model for one drive: ``y' = rhs(t, y)``, ``y0`` the
    static state (zeros). Same physics as the compiled kernel (Hertz, Hunt-Crossley dashpots,
    block-modal resonator damping, ends)."""
    M, _, C, _ = linear_matrices(chain, drive.direction, drive.kind)
    N, J = chain.n, chain.n_modes
    D = N * (J + 1)
    # remove the linearised contacts from K and C: contacts are evaluated nonlinearly below
    Kb = np.zeros((D, D))
    kr = _oriented(chain, drive.direction)[2]
    for i in range(N):
        for j in range(J):
            a, b_ = i, N + i * J + j
            Kb[a, a] += kr[i, j]
            Kb[b_, b_] += kr[i, j]
            Kb[a, b_] -= kr[i, j]
            Kb[b_, a] -= kr[i, j]
    dash = chain.contact_dashpot_Ns_per_m()
    if drive.direction == "rtl":
        dash = dash[::-1]
    Cc = np.zeros((D, D))
    for jc in range(1, N):
        Cc[jc - 1, jc - 1] += dash[jc]
        Cc[jc, jc] += dash[jc]
        Cc[jc - 1, jc] -= dash[jc]
        Cc[jc, jc - 1] -= dash[jc]
    if drive.kind == "displacement":
        Cc[0, 0] += dash[0]
    if chain.far_end == "wall":
        Cc[N - 1, N - 1] += dash[N]
    Cres = C - Cc
    minv = 1.0 / np.diag(M)
    chi = chain.hunt_crossley_chi_s_per_m()
    d0 = chain.rest_overlap_m  # [N+1] rest overlap of each contact (gaps: negative)
    if drive.direction == "rtl":
        chi = chi[::-1]
        d0 = d0[::-1]
    beta, f0 = chain.beta_c, chain.f0_N
    eps = 1e-7 / max(drive.burst.f_center_Hz if drive.burst else 1e4, 1.0)

    def drive_at(t: float) -> tuple[float, float]:
        v = float(drive.value(np.array([t]))[0])
        dv = float(drive.value(np.array([t + eps]))[0] - drive.value(np.array([t - eps]))[0])
        return v, dv / (2 * eps)

    def hc(d: NDArray[np.float64], dd: NDArray[np.float64], c: NDArray[np.float64]):  # type: ignore[no-untyped-def]
        dp = np.maximum(d, 0.0)
        return np.maximum(beta * dp * np.sqrt(dp) * (1.0 + c * dd), 0.0)

    def rhs(t: float, y: NDArray[np.float64]) -> NDArray[np.float64]:
        x, v = y[:D], y[D:]
        u, ud = x[:N], v[:N]
        f = -(Kb @ x) - (Cres @ v)
        val, dval = drive_at(t)
        inner = hc(d0[1:N] + u[:-1] - u[1:], ud[:-1] - ud[1:], chi[1:N])
        f[: N - 1] -= inner
        f[1:N] += inner
        if drive.kind == "displacement":
            f[0] += float(hc(np.array([d0[0] + val - u[0]]), np.array([dval - ud[0]]), chi[:1])[0])
        else:
            f[0] += f0 + val
        if chain.far_end == "wall":
            f[N - 1] -= float(hc(np.array([d0[N] + u[-1]]), np.array([ud[-1]]), chi[N:])[0])
        else:
            f[N - 1] -= f0
        return np.concatenate([v, f * minv])

    return rhs, np.zeros(2 * D)
