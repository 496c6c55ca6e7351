"""A sufficient condition for the stability of a symmetric splitting's step, from half a step.

The step map ``M`` ([2D, 2D]) of a linearised chain window (:mod:`sim_backend.dem.step_limit`)
under a palindromic splitting ``D(a_0 h) K(b_0 h) ... K(b_{m-1} h) D(a_m h)`` is the product of
its stages ``S_1 ... S_j`` followed by the same stages in reverse order (the middle one cut in
two halves). Every stage is time-reversible, ``R S R = S^-1`` with ``R = diag(I, -I)``, so with
``X = S_j ... S_1`` the *half map* (the first half of the step; :func:`half_map`),

    M = (S_1 ... S_j) X = R X^-1 R X.

Write ``X = [[Xa, Xb], [Xc, Xd]]``. ``X`` is symplectic: ``Xa Xb^T``, ``Xc Xd^T``, ``Xb^T Xd`` are
symmetric and ``Xd^T Xa - Xb^T Xc = I``. Hence ``M = [[A, B], [C, A^T]]`` with

    A = Xd^T Xa + Xb^T Xc,    B = 2 Xb^T Xd,    1 + A = 2 Xd^T Xa,    1 - A = -2 Xb^T Xc.

The step is stable when the eigenvalues ``c`` of ``A`` lie in (-1, 1) (each ``c`` is the pair
``c +- i sqrt(1 - c^2)`` of ``M`` on the unit circle), which holds when ``(1 + A) B`` and
``(1 - A) B`` are symmetric positive definite (then ``B`` is too, as their half-sum, and ``A`` is
similar to a symmetric matrix whose ``1 +- c`` are positive). These two are congruent to the half
map's own products:

    (1 + A) B = 4 Xd^T (Xa Xb^T) Xd,      (1 - A) B = 4 Xb^T (-Xc Xd^T) Xb,

so the step is stable when ``Xa Xb^T`` and ``-Xc Xd^T`` are positive definite (which also makes
``Xb`` and ``Xd`` invertible): two [D, D] products and two Cholesky factorisations (LAPACK
``dpotrf``) of half a step, no eigenvalues and no compiled code (:func:`certified`). The
condition is strict (``|c| < 1``), so it never calls an unstable step stable; it can fail on a
stable one, which the caller then decides as before.

For the contacts off (stiffness 0) ``X`` is the drift ``D(h / 2)``: ``Xa Xb^T`` and ``-Xc Xd^T``
are ``diag(sin(w h) / 2w)`` and ``diag(w sin(w h) / 2)``, positive for the elastic modes exactly
when ``h w_top < pi`` (the small-step regime of
:func:`sim_backend.dem.step_limit.largest_stable_step`) and zero for the rigid translations, which
any contact stiffness then holds (a window always has a contact at its left end).
:func:`certified` refuses any step outside that regime.

What the caller concludes from one certificate: :func:`sim_backend.dem.step_limit.stable_up_to`
certifies the largest contact stiffness it needs (the grid point at or above the run's largest
overlap) and takes every smaller stiffness, down to the preload's, as stable too. That rests on
the certified stiffnesses forming one interval from 0. For Strang it is proven. With the drift's
diagonals ``C``, ``S``, ``W`` (cosine, sine of ``w h / 2``, and ``w``), the modal contact matrix
``G = Phi Kc Phi^T`` (positive semi-definite) and ``kappa = k h / 2``: ``Xa Xb^T = C S W^-1`` does
not depend on ``k``, and

    -Xc Xd^T = (W S + kappa G C)(C - kappa W^-1 S G) = Y T Z,
    Y = W S C^-1 + kappa G,   T = C S W^-1,   Z = W C S^-1 - kappa G,

with ``Y`` and ``T`` positive definite (``kappa > 0``). As ``Y^-1 (Y T Z) = T Z``, whose
eigenvalues have the signs of ``Z``'s (Sylvester), the symmetric ``Y T Z`` is positive definite
exactly when ``Z`` is, and ``Z`` only loses definiteness as ``kappa`` grows: the certified
stiffnesses are ``(0, k_1)``. For the fourth- and sixth-order splittings it was measured (``tests/
dem/test_stability_certificate.py`` keeps a sample): MEASURED_HERE. (The grid scan that the
certificate replaces checks grid points only, and rests on the stable stiffnesses forming an
interval too.) Past the regime, where a step is stable only in narrow bands, the certificate is
not used.

Cost on the default chain (D = 124, blanes-moan4: 3 drifts and 3 kicks in half a step), one BLAS
thread: about 0.9 ms, of which 0.5 ms the half map.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from sim_backend.dem.kernel import drift_coefficients

__all__ = ["certified", "half_map", "half_stages"]


def half_stages(
    a_w: Sequence[float], b_w: Sequence[float]
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The first half of the palindromic splitting with drift weights ``a_w`` ([m + 1]) and kick
    weights ``b_w`` ([m]): ``(drifts, kicks)``, applied ``D(drifts[0]) K(kicks[0]) D(drifts[1])
    ...``, alternating, drifts first; the middle stage (a kick for odd ``m``, a drift for even
    ``m``) halved. Weights are fractions of the step."""
    a = tuple(float(x) for x in a_w)
    b = tuple(float(x) for x in b_w)
    if a != a[::-1] or b != b[::-1] or len(a) != len(b) + 1:
        raise ValueError("half_stages: the splitting is not palindromic")
    m = len(b)
    if m % 2:  # odd: ... D(a_j) K(b_j / 2), j = (m - 1) / 2
        j = (m - 1) // 2
        return a[: j + 1], (*b[:j], 0.5 * b[j])
    j = m // 2  # even: ... K(b_{j-1}) D(a_j / 2)
    return (*a[:j], 0.5 * a[j]), b[:j]


def _contact_forces(u: NDArray[np.float64], left: bool, right: bool) -> NDArray[np.float64]:
    """``Kc u`` for unit contact stiffness: ``u`` [n, C] primary displacements (m), each cylinder
    pushed by its neighbours (and by fixed walls at the ends where ``left`` / ``right``)."""
    f = np.zeros_like(u)
    d = u[1:] - u[:-1]  # [n - 1, C] compression of the inner contacts
    f[:-1] -= d
    f[1:] += d
    if left:
        f[0] += u[0]
    if right:
        f[-1] += u[-1]
    return f


def half_map(
    phi: NDArray[np.float64],
    omega: NDArray[np.float64],
    left: bool,
    right: bool,
    a_w: Sequence[float],
    b_w: Sequence[float],
    h: float,
    k: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The half map ``X`` (module docstring) of one window at step ``h`` (s), contact stiffness
    ``k`` (N/m): ``(Q, P)``, each [D, 2D] (``D = n K``), the modal positions and momenta after
    half a step as linear functions of the initial ``(q, p)``; ``[[Xa, Xb], [Xc, Xd]]`` is
    ``[[Q[:, :D], Q[:, D:]], [P[:, :D], P[:, D:]]]``.

    phi: [n, K] primary components of the block modes (1/sqrt(kg)); omega: [n, K] their angular
    frequencies (rad/s); left, right: contacts beyond the window's ends; a_w, b_w: the splitting's
    weights (:data:`sim_backend.dem.simulation.INTEGRATORS`).

    A drift is the exact flow of each mode; a kick acts through the primary masses only
    (``u = Phi^T q``, forces ``-k Kc u`` spread back by ``Phi``), O(n K D) per kick. All the
    drifts' coefficients come from one :func:`sim_backend.dem.kernel.drift_coefficients` call.
    """
    drifts, kicks = half_stages(a_w, b_w)
    n, K = phi.shape
    D = n * K
    om = np.asarray(omega, dtype=np.float64).ravel()
    coef = drift_coefficients(om, np.zeros_like(om), np.asarray(drifts)[:, None] * h)  # [S, D, 4]
    coef = np.ascontiguousarray(coef.transpose(0, 2, 1)[:, :, :, None])  # [S, 4, D, 1]
    c = coef[0]
    i = np.arange(D)
    Q = np.zeros((D, 2 * D))
    P = np.zeros((D, 2 * D))
    Q[i, i], Q[i, D + i], P[i, i], P[i, D + i] = c[0, :, 0], c[1, :, 0], c[2, :, 0], c[3, :, 0]
    t1 = np.empty_like(Q)  # work arrays: the stages update Q and P in place
    t2 = np.empty_like(Q)
    phi_col = phi[:, :, None]  # [n, K, 1]
    for s in range(1, len(drifts) + len(kicks)):
        if s % 2:  # a kick: P -= b h k Phi Kc Phi^T Q
            u = np.matmul(phi[:, None, :], Q.reshape(n, K, 2 * D))[:, 0, :]  # [n, 2D]
            f = (-(kicks[s // 2] * h * k)) * _contact_forces(u, left, right)
            np.multiply(phi_col, f[:, None, :], out=t1.reshape(n, K, 2 * D))
            P += t1
        else:  # a drift: (Q, P) <- (c0 Q + c1 P, c2 Q + c3 P), mode by mode
            c = coef[s // 2]
            np.multiply(Q, c[2], out=t1)
            np.multiply(P, c[1], out=t2)
            Q *= c[0]
            Q += t2
            P *= c[3]
            P += t1
    return Q, P


def _positive_definite(a: NDArray[np.float64]) -> bool:
    """Whether LAPACK's Cholesky factorisation of the symmetric part of ``a`` succeeds."""
    from scipy.linalg.lapack import dpotrf  # scipy.linalg is loaded by the block modes already

    _, info = dpotrf(0.5 * (a + a.T), lower=1, clean=0, overwrite_a=1)
    return bool(info == 0)


def certified(
    phi: NDArray[np.float64],
    omega: NDArray[np.float64],
    left: bool,
    right: bool,
    a_w: Sequence[float],
    b_w: Sequence[float],
    h: float,
    k: float,
) -> bool:
    """Whether step ``h`` (s) of the palindromic splitting ``(a_w, b_w)`` is certified stable on
    the window at contact stiffness ``k`` (N/m): ``h w_top < pi``, and ``Xa Xb^T`` and
    ``-Xc Xd^T`` of the half map positive definite (module docstring). Arguments as
    :func:`half_map`. ``False`` means "not certified", not "unstable"."""
    w_top = float(np.max(omega)) if np.size(omega) else 0.0
    if not (h > 0.0 and h * w_top < math.pi):
        return False
    Q, P = half_map(phi, omega, left, right, a_w, b_w, h, k)
    D = Q.shape[0]
    if not _positive_definite(Q[:, :D] @ Q[:, D:].T):
        return False
    return _positive_definite(-(P[:, :D] @ P[:, D:].T))
