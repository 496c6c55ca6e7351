"""The one-step map of a linearised chain window, for many contact stiffnesses at once (compiled).

The map of one splitting step ``D(a_0 h) K(b_0 h) ... K(b_{m-1} h) D(a_m h)`` on the modal state
``(q, p)`` of a window of ``n`` cylinders with ``K`` block modes each (``D = n K``; see
:mod:`sim_backend.dem.step_limit`) is built column by column: column ``j`` is the trajectory of one
step started from the unit vector ``e_j``. A drift acts mode by mode, a kick couples a cylinder to
its two neighbours only (the contacts: a 3-point stencil on the primary displacements
``u = Phi^T q``), so after ``s`` kicks a column started in cylinder ``c`` is nonzero only in
cylinders ``c - s .. c + s``; the kernel works on that band alone (zeros are never computed), for
the ``2 K`` columns started in one cylinder together (the innermost loop, over those columns, is a
short SIMD loop). Only the position rows ``q1 = A q0 + B p0`` are returned (the stability test
needs no more). The result equals the dense product of the stage matrices to round-off.

Cost on the default chain (n = 31, K = 4, blanes-moan4: 7 drifts, 6 kicks), one thread: 0.07 to
0.1 ms per stiffness (8 stiffnesses in 0.55 ms), against 1.5 to 2 ms for the numpy map
(``step_limit._step_map``). Compiled on first use (about 1 s) into the user's cache folder like
the kernel (:mod:`sim_backend.dem.kernel_cache`); a new process loads it in 2 to 5 ms.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from sim_backend.dem.kernel_cache import install_cache_locator

install_cache_locator()  # compiled code goes to the user's cache folder, not next to the sources

__all__ = ["position_blocks", "warm_up"]


@numba.njit(cache=True, nogil=True)
def _position_blocks(
    phi: NDArray[np.float64],
    coef: NDArray[np.float64],
    stage_coef: NDArray[np.int64],
    kick_h: NDArray[np.float64],
    stiffness: NDArray[np.float64],
    left: bool,
    right: bool,
    symmetric_b: bool,
    A: NDArray[np.float64],
    B: NDArray[np.float64],
    q: NDArray[np.float64],
    p: NDArray[np.float64],
    u: NDArray[np.float64],
    f: NDArray[np.float64],
) -> None:
    n, K = phi.shape
    D = n * K
    C = 2 * K
    n_kick = kick_h.size
    for o in range(stiffness.size):
        k = stiffness[o]
        for cyl in range(n):
            lo = cyl
            hi = cyl + 1  # cylinders [lo, hi) may be nonzero
            # the first drift applied to the unit vectors of this cylinder's modes
            c0 = stage_coef[0]
            for r in range(lo * K, hi * K):
                for j in range(C):
                    q[r, j] = 0.0
                    p[r, j] = 0.0
            for m in range(K):
                r = cyl * K + m
                q[r, m] = coef[c0, r, 0]
                p[r, m] = coef[c0, r, 2]
                q[r, K + m] = coef[c0, r, 1]
                p[r, K + m] = coef[c0, r, 3]
            for s in range(n_kick):
                if s > 0:  # drift a_s
                    cs = stage_coef[s]
                    for r in range(lo * K, hi * K):
                        a0 = coef[cs, r, 0]
                        a1 = coef[cs, r, 1]
                        a2 = coef[cs, r, 2]
                        a3 = coef[cs, r, 3]
                        for j in range(C):
                            qq = q[r, j]
                            pp = p[r, j]
                            q[r, j] = a0 * qq + a1 * pp
                            p[r, j] = a2 * qq + a3 * pp
                # kick b_s: u = Phi^T q on [lo, hi), forces on [lo - 1, hi + 1)
                for i in range(lo, hi):
                    for j in range(C):
                        u[i, j] = 0.0
                    for m in range(K):
                        ph = phi[i, m]
                        r = i * K + m
                        for j in range(C):
                            u[i, j] += ph * q[r, j]
                new_lo = max(lo - 1, 0)
                new_hi = min(hi + 1, n)
                for i in range(new_lo, new_hi):
                    if i < lo or i >= hi:  # entering the band: zero state there
                        for m in range(K):
                            r = i * K + m
                            for j in range(C):
                                q[r, j] = 0.0
                                p[r, j] = 0.0
                g = -kick_h[s] * k
                for i in range(new_lo, new_hi):
                    diag = 0.0  # contacts of cylinder i
                    if i > 0 or left:
                        diag += 1.0
                    if i < n - 1 or right:
                        diag += 1.0
                    for j in range(C):
                        acc = 0.0
                        if lo <= i < hi:
                            acc = diag * u[i, j]
                        if lo <= i - 1 < hi:
                            acc -= u[i - 1, j]
                        if lo <= i + 1 < hi:
                            acc -= u[i + 1, j]
                        f[i, j] = g * acc
                for i in range(new_lo, new_hi):
                    for m in range(K):
                        ph = phi[i, m]
                        r = i * K + m
                        for j in range(C):
                            p[r, j] += ph * f[i, j]
                lo = new_lo
                hi = new_hi
            # the last drift: positions only
            cs = stage_coef[n_kick]
            for r in range(lo * K, hi * K):
                a0 = coef[cs, r, 0]
                a1 = coef[cs, r, 1]
                for m in range(K):
                    col = cyl * K + m
                    A[o, r, col] = a0 * q[r, m] + a1 * p[r, m]
                    B[o, r, col] = a0 * q[r, K + m] + a1 * p[r, K + m]
        if symmetric_b:  # B is symmetric (a time-reversible splitting): its symmetric part
            for r in range(D):
                for col in range(r):
                    b = 0.5 * (B[o, r, col] + B[o, col, r])
                    B[o, r, col] = b
                    B[o, col, r] = b


def position_blocks(
    phi: NDArray[np.float64],
    coef: NDArray[np.float64],
    stage_coef: NDArray[np.int64],
    kick_h: NDArray[np.float64],
    stiffness: NDArray[np.float64],
    left: bool,
    right: bool,
    symmetric_b: bool = False,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The position blocks ``(A, B)`` ([M, D, D] each) of the one-step map for ``M`` contact
    stiffnesses: positions after one step ``q1 = A q0 + B p0``.

    phi: [n, K] primary components of the window's block modes.
    coef: [S, D, 4] drift coefficients (:func:`sim_backend.dem.kernel.drift_coefficients`) of the
        S distinct drift lengths; stage_coef: [m + 1] which of them each drift uses.
    kick_h: [m] kick lengths ``b_s h`` (s).
    stiffness: [M] contact stiffnesses (N/m); left, right: contacts beyond the window's ends.
    symmetric_b: return the symmetric part ``(B + B^T) / 2`` of ``B`` (for a time-reversible
        splitting, whose ``B`` is symmetric to round-off).
    """
    n, K = phi.shape
    D = n * K
    M = stiffness.size
    A = np.zeros((M, D, D))
    B = np.zeros((M, D, D))
    _position_blocks(
        np.ascontiguousarray(phi, dtype=np.float64),
        np.ascontiguousarray(coef, dtype=np.float64),
        np.ascontiguousarray(stage_coef, dtype=np.int64),
        np.ascontiguousarray(kick_h, dtype=np.float64),
        np.ascontiguousarray(stiffness, dtype=np.float64),
        bool(left),
        bool(right),
        bool(symmetric_b),
        A,
        B,
        np.zeros((D, 2 * K)),  # work: positions, momenta of the 2 K columns, displacements, forces
        np.zeros((D, 2 * K)),
        np.zeros((n, 2 * K)),
        np.zeros((n, 2 * K)),
    )
    return A, B


def warm_up() -> None:
    """Compile (or load) the compiled map now, on a one-cylinder window: ``biafc warmup`` calls
    it, so that the first stability scan of a chain that ships no verdicts (a modified chain, a
    study's cells) does not compile during a run."""
    position_blocks(
        np.ones((1, 1)),
        np.zeros((1, 1, 4)),
        np.zeros(2, dtype=np.int64),
        np.ones(1),
        np.ones(1),
        left=True,
        right=True,
    )
