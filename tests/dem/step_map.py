"""The one-step map of a linearised chain window, for many contact stiffnesses at once, and its
stability test (compiled).

The map of one splitting step ``D(a_0 h) K(b_0 h) ... K(b_{m-1} h) D(a_m h)`` on the modal state
``(q, p)`` of a window of ``n`` cylinders with ``K`` block modes each (``D = n K``; see
:mod:`sim_backend.dem.step_limit`) is built column by column: column ``j`` is the trajectory of one
step started from the unit vector ``e_j``. A drift acts mode by mode, a kick couples a cylinder to
its two neighbours only (the contacts: a 3-point stencil on the primary displacements
``u = Phi^T q``), so after ``s`` kicks a column started in cylinder ``c`` is nonzero only in
cylinders ``c - s .. c + s``; the kernel works on that band alone (zeros are never computed), for
the ``2 K`` columns started in one cylinder together (the innermost loop, over those columns, is a
short SIMD loop). Only the position rows ``q1 = A q0 + B p0`` are kept (the stability test needs
no more). The result equals the dense product of the stage matrices to round-off.

:func:`stability_codes` also decides, in the same compiled call, whether each map is stable: the
two Cholesky factorisations of ``C B - A B`` and ``C B + A B`` (:mod:`sim_backend.dem.step_limit`),
with BLAS ``dgemm`` and LAPACK ``dpotrf`` (scipy's, called through numba's own C helpers), so a
scan of many stiffnesses has no Python step per stiffness; a failed factorisation is reported and
the caller decides by the eigenvalues.

Since 2026-11-27 no check uses it: :mod:`sim_backend.dem.step_limit` builds the same blocks from
half a step's map with numpy (:mod:`sim_backend.dem.stability_certificate`), which needs nothing
compiled (this module compiled for 3 s on a fresh install before the first refusal of an unstable
step, and took 5-8 ms to load in every new process). It moved from ``sim_backend/dem`` to the
tests, as the independent implementation they compare those blocks and verdicts with
(``tests/dem/test_setup_cost.py``, ``tests/dem/test_stability_certificate.py``).

Cost on the default chain (n = 31, K = 4, blanes-moan4: 7 drifts, 6 kicks), one thread: a scan of
8 stiffnesses (blocks and factorisations) 2.2 ms, against 2.7 ms for the blocks here and the
factorisations in Python (interleaved, fresh processes). One compiled function serves both (one
cached library to load): compiled on first use (1.4 s) into the user's cache folder like the
kernel (:mod:`sim_backend.dem.kernel_cache`); a new process loads it in 5 to 8 ms (2.7 ms of it
LLVM parsing the library's bitcode), under numba's process-wide compiler lock.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from numba import types
from numpy.typing import NDArray

from sim_backend.dem.kernel_cache import install_cache_locator

install_cache_locator()  # compiled code goes to the user's cache folder, not next to the sources

__all__ = [
    "B_INDEFINITE",
    "STABLE",
    "UNDECIDED",
    "position_blocks",
    "stability_codes",
]

#: :func:`stability_codes`: every ``c`` in [-C, C] (stable)
STABLE = 1
#: :func:`stability_codes`: ``B`` not positive definite (past the small-step regime: unstable)
B_INDEFINITE = 0
#: :func:`stability_codes`: a factorisation failed: the eigenvalues decide
UNDECIDED = 2

# BLAS dgemm and LAPACK dpotrf (scipy's, as scipy.linalg's own) through numba's C helpers, the
# functions behind numba's np.dot and np.linalg: called directly, they add no code to the compiled
# library (numba's np.linalg.cholesky with its exception handling doubled it, and the time a new
# process takes to load it)
_F64P = types.CPointer(types.float64)
_xxgemm: Any = types.ExternalFunction(
    "numba_xxgemm",
    types.intc(types.char, types.char, types.char, types.intp, types.intp, types.intp, _F64P,
               _F64P, types.intp, _F64P, types.intp, _F64P, _F64P, types.intp),
)  # fmt: skip
_xxpotrf: Any = types.ExternalFunction(
    "numba_xxpotrf", types.intc(types.char, types.char, types.intp, _F64P, types.intp)
)
_KIND = ord("d")
_NO_TRANS = ord("n")
_LOWER = ord("L")


@numba.njit(nogil=True)
def _band_blocks(
    phi: NDArray[np.float64],
    coef: NDArray[np.float64],
    stage_coef: NDArray[np.int64],
    kick_h: NDArray[np.float64],
    k: float,
    left: bool,
    right: bool,
    A: NDArray[np.float64],
    B: NDArray[np.float64],
    q: NDArray[np.float64],
    p: NDArray[np.float64],
    u: NDArray[np.float64],
    f: NDArray[np.float64],
) -> None:
    """Position blocks ``A``, ``B`` ([D, D], zero outside the band on entry) of the step map at
    one contact stiffness ``k`` (N/m); ``q``, ``p``, ``u``, ``f``: work arrays."""
    n, K = phi.shape
    C = 2 * K
    n_kick = kick_h.size
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
                A[r, col] = a0 * q[r, m] + a1 * p[r, m]
                B[r, col] = a0 * q[r, K + m] + a1 * p[r, K + m]


@numba.njit(nogil=True, inline="always")
def _symmetrise(B: NDArray[np.float64]) -> None:
    """``B <- (B + B^T) / 2`` in place ([D, D])."""
    D = B.shape[0]
    for r in range(D):
        for col in range(r):
            b = 0.5 * (B[r, col] + B[col, r])
            B[r, col] = b
            B[col, r] = b


@numba.njit(nogil=True, inline="always")
def _positive_definite(a: NDArray[np.float64]) -> bool:
    """Whether LAPACK's Cholesky factorisation of the symmetric ``a`` ([D, D], C order,
    overwritten) succeeds: ``dpotrf('L')`` on its memory read in Fortran order, i.e. on the upper
    triangle of ``a``, as ``scipy.linalg.lapack.dpotrf(a.T, lower=1)``."""
    n = a.shape[0]
    return _xxpotrf(_KIND, _LOWER, n, a.ctypes, n) == 0


@numba.njit(nogil=True, inline="always")
def _test(
    A: NDArray[np.float64],
    B: NDArray[np.float64],
    c_tol: float,
    small_step: bool,
    ab: NDArray[np.float64],
    work: NDArray[np.float64],
    one: NDArray[np.float64],
    zero: NDArray[np.float64],
) -> int:
    """The stability code of one map from its position blocks ``A``, ``B`` ([D, D], ``B``
    symmetric): ``c_tol B - A B`` and ``c_tol B + A B`` positive definite, or why not."""
    D = A.shape[0]
    # ab = A @ B (symmetric to round-off), as numpy's matmul calls it: in Fortran order
    # ab^T = B^T A^T
    _xxgemm(_KIND, _NO_TRANS, _NO_TRANS, D, D, D, one.ctypes, B.ctypes, D, A.ctypes, D,
            zero.ctypes, ab.ctypes, D)  # fmt: skip
    for r in range(D):
        for col in range(D):
            work[r, col] = c_tol * B[r, col] - ab[r, col]
    if _positive_definite(work):
        for r in range(D):
            for col in range(D):
                work[r, col] = c_tol * B[r, col] + ab[r, col]
        if _positive_definite(work):
            return STABLE
    if small_step:
        for r in range(D):
            for col in range(D):
                work[r, col] = B[r, col]
        if not _positive_definite(work):
            return B_INDEFINITE
    return UNDECIDED


@numba.njit(cache=True, nogil=True)
def _scan(
    phi: NDArray[np.float64],
    coef: NDArray[np.float64],
    stage_coef: NDArray[np.int64],
    kick_h: NDArray[np.float64],
    stiffness: NDArray[np.float64],
    left: bool,
    right: bool,
    symmetric_b: bool,
    test: bool,
    c_tol: float,
    small_step: bool,
    A: NDArray[np.float64],
    B: NDArray[np.float64],
    q: NDArray[np.float64],
    p: NDArray[np.float64],
    u: NDArray[np.float64],
    f: NDArray[np.float64],
    ab: NDArray[np.float64],
    work: NDArray[np.float64],
    one: NDArray[np.float64],
    zero: NDArray[np.float64],
    codes: NDArray[np.int64],
) -> None:
    """Position blocks of every stiffness into ``A``, ``B``; with ``test``, their stability codes
    into ``codes`` too (``B`` symmetrised)."""
    for o in range(stiffness.size):
        _band_blocks(phi, coef, stage_coef, kick_h, stiffness[o], left, right, A[o], B[o], q, p,
                     u, f)  # fmt: skip
        if symmetric_b or test:  # B is symmetric (a time-reversible splitting): its symmetric part
            _symmetrise(B[o])
        if test:
            codes[o] = _test(A[o], B[o], c_tol, small_step, ab, work, one, zero)


def _run(
    phi: NDArray[np.float64],
    coef: NDArray[np.float64],
    stage_coef: NDArray[np.int64],
    kick_h: NDArray[np.float64],
    stiffness: NDArray[np.float64],
    left: bool,
    right: bool,
    symmetric_b: bool,
    test: bool,
    c_tol: float,
    small_step: bool,
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    n, K = phi.shape
    D = n * K
    M = stiffness.size
    A = np.zeros((M, D, D))
    B = np.zeros((M, D, D))
    codes = np.full(M, -1, dtype=np.int64)
    d = D if test else 0
    _scan(  # copies: writable C arrays, one signature whatever the caller holds (read-only modes)
        np.array(phi, dtype=np.float64, order="C"),
        np.array(coef, dtype=np.float64, order="C"),
        np.array(stage_coef, dtype=np.int64, order="C"),
        np.array(kick_h, dtype=np.float64, order="C"),
        np.array(stiffness, dtype=np.float64, order="C"),
        bool(left),
        bool(right),
        bool(symmetric_b),
        bool(test),
        float(c_tol),
        bool(small_step),
        A,
        B,
        np.zeros((D, 2 * K)),  # work: positions, momenta of the 2 K columns, displacements, forces
        np.zeros((D, 2 * K)),
        np.zeros((n, 2 * K)),
        np.zeros((n, 2 * K)),
        np.empty((d, d)),  # A B
        np.empty((d, d)),  # the matrix factorised
        np.ones(1),
        np.zeros(1),
        codes,
    )
    return codes, A, B


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
    _, A, B = _run(phi, coef, stage_coef, kick_h, stiffness, left, right, symmetric_b, False,
                   1.0, False)  # fmt: skip
    return A, B


def stability_codes(
    phi: NDArray[np.float64],
    coef: NDArray[np.float64],
    stage_coef: NDArray[np.int64],
    kick_h: NDArray[np.float64],
    stiffness: NDArray[np.float64],
    left: bool,
    right: bool,
    c_tol: float,
    small_step: bool = False,
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """The stability test of a time-reversible splitting's step map for ``M`` contact stiffnesses
    in one compiled call (see :mod:`sim_backend.dem.step_limit`): its position blocks ``A`` and
    ``B`` (``B`` symmetrised), then every ``c`` (eigenvalue of ``A``) in [-c_tol, c_tol] when
    ``c_tol B - A B`` and ``c_tol B + A B`` are positive definite (two Cholesky factorisations).

    Arguments as :func:`position_blocks`; c_tol: the bound on ``|c|``; small_step: when a
    factorisation failed, also factorise ``B`` and report :data:`B_INDEFINITE` when it is not
    positive definite.

    Returns ``(codes, A, B)``: codes [M] (:data:`STABLE`, :data:`B_INDEFINITE` or
    :data:`UNDECIDED`: a factorisation failed, the eigenvalues of ``A`` decide), ``A``, ``B``
    [M, D, D].
    """
    return _run(phi, coef, stage_coef, kick_h, stiffness, left, right, True, True, c_tol,
                small_step)  # fmt: skip
