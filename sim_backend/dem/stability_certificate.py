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
dem/test_stability_certificate.py`` keeps a sample), by the compiled test's codes: 16 chains (the
default; preloads 0.5, 1, 6 and 20 N; contacts 3x and 100x stiffer; 13, 21 and 80 cylinders, the
last checked on windows; 2 and 6 resonators; graded 80-120 mm; a free far end; light primaries;
Euler-Bernoulli beams), all five splittings, 40 steps from 0.03 to 0.995 of the regime
(``h w_top / pi``) and 160 stiffnesses from 0.01 to 1000 times the preload's: 3,200 cases and
512,000 points, 383,896 of them certified, every one stable, and the certified stiffnesses an
interval from the bottom of the ladder in every case but one (yoshida6 at 0.995 of the regime).
Nearer the edge (6 chains of 7 to 21 cylinders with 1 to 6 resonators, 50 steps from 0.5 to
0.999 of the regime, 200 stiffnesses: 1,500 cases) a certificate stood above an unstable
stiffness in 6 cases, all yoshida6 at 0.989 of the regime; so the caller uses the certificate for
steps up to 0.9 of it (:data:`sim_backend.dem.step_limit.CERTIFIED_STEP_FRACTION`). (The grid
scan that the certificate replaces checks grid points only, and rests on the stable stiffnesses
forming an interval too.) Past the regime, where a step is stable only in narrow bands, the
certificate is not used.

Cost on the default chain (D = 124, blanes-moan4: 3 drifts and 3 kicks in half a step), one BLAS
thread: about 0.9 ms, of which 0.5 ms the half map.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

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


@functools.lru_cache(maxsize=32)
def _band(n: int, K: int, s: int, left: bool, right: bool) -> tuple[NDArray[Any], ...]:
    """The band layout of :func:`half_map` for ``n`` cylinders, ``K`` modes each, ``s`` kicks:
    ``rc`` [n, W] the cylinder of each band row (clipped into the window), ``valid`` [n, W]
    whether it is inside, ``diag`` [n, W] its number of contacts (0 outside), and the dense
    ``band``, ``dense``: the flat indices of the band entries [n, W, K, 2K] inside the window
    (``W = 2 s + 1``) and of their places in the dense [D, 2D] map. Read-only (cached)."""
    W = 2 * s + 1
    D = n * K
    r = np.arange(n)[:, None] + np.arange(W)[None, :] - s
    valid = (r >= 0) & (r < n)
    rc = np.clip(r, 0, n - 1)
    diag = ((rc > 0) | left).astype(np.float64) + ((rc < n - 1) | right).astype(np.float64)
    diag = np.where(valid, diag, 0.0)
    m = np.arange(K)
    j = np.arange(2 * K)
    shape = (n, W, K, 2 * K)
    rows = np.broadcast_to(rc[:, :, None, None] * K + m[None, None, :, None], shape)
    col_j = np.where(j < K, j, D + j - K)  # a position unit of mode j, or a momentum unit
    cols = np.broadcast_to(np.arange(n)[:, None, None, None] * K + col_j, shape)
    sel = np.broadcast_to(valid[:, :, None, None], shape)
    # flat indices: of the band entries inside the window, and of their places in the dense map
    band = np.flatnonzero(sel)
    dense = (rows * (2 * D) + cols)[sel]
    out = (rc, valid, diag, band, dense)
    for arr in out:
        arr.setflags(write=False)
    return out


def _rotations(omega: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    """The undamped drifts' coefficients [S, D, 4] (a, b, c, d: ``q1 = a q0 + b p0``, ``p1 = c q0
    + d p0``) of the modes ``omega`` [D] (rad/s) over the times ``t`` [S] (s): what
    :func:`sim_backend.dem.kernel.drift_coefficients` gives with no damping (``tests/dem/
    test_stability_certificate.py``), without its damping's arithmetic."""
    rigid = omega <= 0.0
    w = np.where(rigid, 1.0, omega)
    th = t[:, None] * omega[None, :]
    c = np.cos(th)
    s = np.sin(th)
    out = np.empty((t.size, omega.size, 4))
    out[..., 0] = c
    out[..., 1] = np.where(rigid, t[:, None], s / w)
    out[..., 2] = -w * s
    out[..., 3] = c
    return out


def _half_band(
    phi: NDArray[np.float64],
    omega: NDArray[np.float64],
    left: bool,
    right: bool,
    a_w: Sequence[float],
    b_w: Sequence[float],
    h: float,
    k: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The half map on its band (:func:`half_map`): ``(Qb, Pb)``, each [n, W, K, 2K], entry
    ``[c, w, m, j]`` the position (momentum) of mode ``m`` of cylinder ``c - s + w`` (zero outside
    the window) started from unit vector ``j`` of cylinder ``c`` (``j < K``: the position of its
    mode ``j``; else the momentum of mode ``j - K``); ``s`` kicks, ``W = 2 s + 1``."""
    drifts, kicks = half_stages(a_w, b_w)
    n, K = phi.shape
    s_max = len(kicks)
    rc, valid, diag, _, _ = _band(n, K, s_max, bool(left), bool(right))
    coef = _rotations(np.asarray(omega, dtype=np.float64).ravel(), np.asarray(drifts) * h)
    first = coef[0].reshape(n, K, 4)
    # the band's coefficients [S, 4, n, W, K, 1] and primary components [n, W, K]
    coef_b = np.moveaxis(coef.reshape(len(drifts), n, K, 4)[:, rc], -1, 1)[..., None]
    phi_b = np.asarray(phi, dtype=np.float64)[rc] * valid[:, :, None]
    # band state: [column cylinder c, row cylinder c - s_max + w, row mode, column j of c]
    Qb = np.zeros((n, 2 * s_max + 1, K, 2 * K))
    Pb = np.zeros_like(Qb)
    m = np.arange(K)  # the first drift applied to the unit vectors
    Qb[:, s_max, m, m], Qb[:, s_max, m, K + m] = first[:, :, 0], first[:, :, 1]
    Pb[:, s_max, m, m], Pb[:, s_max, m, K + m] = first[:, :, 2], first[:, :, 3]
    for st in range(1, len(drifts) + len(kicks)):
        if st % 2:  # a kick: P -= b h k Phi Kc Phi^T Q
            u = np.matmul(phi_b[:, :, None, :], Qb)[:, :, 0, :]  # [n, W, 2K]
            f = diag[:, :, None] * u
            f[:, 1:] -= u[:, :-1]
            f[:, :-1] -= u[:, 1:]
            f *= (-(kicks[st // 2] * h * k)) * valid[:, :, None]
            Pb += phi_b[:, :, :, None] * f[:, :, None, :]
        else:  # a drift: (Q, P) <- (c0 Q + c1 P, c2 Q + c3 P), mode by mode
            c = coef_b[st // 2]
            t = Qb * c[2]
            Qb *= c[0]
            Qb += Pb * c[1]
            Pb *= c[3]
            Pb += t
    return Qb, Pb


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
    (``u = Phi^T q``, forces ``-k Kc u`` spread back by ``Phi``) and couples a cylinder to its
    neighbours, so after ``s`` kicks the columns started in cylinder ``c`` are nonzero in
    cylinders ``c - s .. c + s`` only: the stages work on that band (``W = 2 s + 1`` cylinders per
    column block, a quarter of the dense map on the default chain), which is then placed in the
    dense ``(Q, P)``.
    """
    n, K = phi.shape
    D = n * K
    Qb, Pb = _half_band(phi, omega, left, right, a_w, b_w, h, k)
    _, _, _, band, dense = _band(n, K, (Qb.shape[1] - 1) // 2, bool(left), bool(right))
    Q = np.zeros((D, 2 * D))
    P = np.zeros((D, 2 * D))
    np.put(Q, dense, np.take(Qb, band))
    np.put(P, dense, np.take(Pb, band))
    return Q, P


@functools.lru_cache(maxsize=32)
def _gram_index(n: int, W: int, K: int) -> NDArray[np.int64]:
    """Flat indices [n W K W K] into the padded [(n + W - 1) K]^2 matrix of :func:`_gram`'s
    blocks: block ``c`` at cylinders ``c .. c + W - 1`` of both sides (read-only, cached)."""
    Dp = (n + W - 1) * K
    at = np.arange(n)[:, None] * K + np.arange(W * K)[None, :]  # [n, W K] padded indices
    idx = (at[:, :, None] * Dp + at[:, None, :]).ravel()
    idx.setflags(write=False)
    return idx


def _gram(left_cols: NDArray[np.float64], right_cols: NDArray[np.float64]) -> NDArray[np.float64]:
    """``X Y^T`` ([D, D]) of two [D, D] matrices given by their column blocks on the band
    (``left_cols``, ``right_cols``: [n, W, K, K], as :func:`_half_band`'s halves): the sum over the
    column cylinders ``c`` of a [W K, W K] block at cylinders ``c - s .. c + s`` (one batched
    product and one ``bincount``), with no dense [D, 2D] map and no [D, D, D] product."""
    n, W, K, _ = left_cols.shape
    s = (W - 1) // 2
    Dp = (n + 2 * s) * K  # padded by s cylinders at both ends
    blocks = np.matmul(
        left_cols.reshape(n, W * K, K), right_cols.reshape(n, W * K, K).transpose(0, 2, 1)
    )
    summed = np.bincount(_gram_index(n, W, K), weights=blocks.ravel(), minlength=Dp * Dp)
    out = np.asarray(summed, dtype=np.float64)  # float64 already (weighted): no copy
    return out.reshape(Dp, Dp)[s * K : (s + n) * K, s * K : (s + n) * K]


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
    Qb, Pb = _half_band(phi, omega, left, right, a_w, b_w, h, k)
    K = Qb.shape[2]
    if not _positive_definite(_gram(Qb[..., :K], Qb[..., K:])):  # Xa Xb^T
        return False
    return _positive_definite(-_gram(Pb[..., :K], Pb[..., K:]))  # -Xc Xd^T
