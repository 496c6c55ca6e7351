"""Largest stable step of the splitting integrators on a chain (linear stability of the step map).

Each step of a splitting is ``D(a_m h) K(b_{m-1} h) ... K(b_0 h) D(a_0 h)``: the drift ``D`` is
the exact flow of every cylinder's free block (primary mass + resonators), a rotation that is
stable for any ``h``; instability can only come from the contact kicks ``K``. Linearise the
contacts about an overlap ``d`` (stiffness ``k(d) = 3/2 beta_c d^(1/2)``) and the step becomes a
constant matrix ``P(h)`` acting on the modal state ``(q, p)`` of the chain ([2D, 2D], D = N (J+1)).
The step is stable when the spectral radius ``rho(P(h)) <= 1`` (the map is symplectic: stable
eigenvalues lie on the unit circle; an unstable one grows by ``rho`` per step).

How it is computed, in about 1 ms per step and overlap on the default chain (D = 124), with
numpy and LAPACK only (nothing to compile): every splitting here is a palindrome, so its step is
``M = R X^-1 R X`` with ``X`` half a step's map, built on the band of cylinders a column can
reach (:func:`sim_backend.dem.stability_certificate.half_map`), and the position blocks below are
``A = Xd^T Xa + Xb^T Xc``, ``B = 2 Xb^T Xd`` (:func:`_position_blocks`; the numpy
:func:`_step_map` builds the whole map for a splitting that is not symmetric, and the compiled
:mod:`tests.dem.step_map`, stage by stage, is the tests' independent reference). Every
splitting here is symmetric, so its step map ``M = [[A, B], [C, A^T]]`` is time-reversible as
well as symplectic: ``R M R = M^-1`` with ``R = diag(I, -I)``. Then ``M + M^-1 = diag(2A,
2A^T)``, so the eigenvalues of ``M`` are the pairs ``lambda = c +- sqrt(c^2 - 1)`` of the
eigenvalues ``c`` of the [D, D] position block ``A``: one eigenvalue problem of size D instead
of 2D. ``B`` is
symmetric, and when it is positive definite (small steps), ``A B`` is symmetric too, so
``L^-1 A L`` (``B = L L^T``) is a symmetric matrix with the same ``c``: real, found by a symmetric
solver, and the step is stable exactly when they all lie in [-1, 1], i.e. when ``B - A B`` and
``B + A B`` are positive definite: two Cholesky factorisations (LAPACK ``dpotrf``) per overlap,
the eigenvalues only when one fails. (The dense 2D x 2D eigenvalues agree to round-off, and the
compiled map's verdicts at every point compared: ``tests/dem/test_setup_cost.py``.)

The largest stable step ``h_max`` is the end of the small-step regime: the smallest ``h`` at which
the step is unstable (``rho(P(h)) > 1 + tol``) or ``B`` stops being positive definite, found by a
geometric scan from ``0.25 pi / w_top`` upwards (ratio 1.08) and a bisection to 0.2 %. ``B`` is
``diag(sin(h w) / w)`` for the drift alone: it loses definiteness when an eigenvalue angle of the
map reaches ``pi``, and (for the drift alone) stays indefinite until that angle reaches ``2 pi``,
a factor of about 2 in ``h``, so the scan does not step over it. Below, the eigenvalues of one
Krein signature keep to the upper half of the unit circle and cannot meet those of the other:
every such step is stable. Above, stable and unstable steps alternate in narrow bands (the angles
of the graded chain's block modes passing ``pi`` one by one): blanes-moan4 on the default chain
is unstable in 85 bands between 6.024 and 8.286 us, the widest under 0.15 % (7.4 us among them),
and stable at 8.22 us, which a scan for the first unstable step reported as the limit
(``docs/stability.md``). For the default chain the limit is the resonance of the stiffest block
mode with the kicks (``h w_top`` near ``pi``): unlike a leapfrog on the whole chain, the limit is
set by the block modes integrated exactly, not by the contact frequency.

Nonlinear stiffening: the Hertz stiffness grows as ``sqrt(d)``, so the contacts are linearised at
a reference overlap ``d_ref = max(4 delta0, delta0 + 2 A_disp, ((F0 + 2 A_force) / beta_c)^(2/3))``
(the drives' peak displacement ``A_disp`` or force ``A_force``, with a margin of 2) as well as at
``delta0``; the step must be stable at both. A chain with no contact stiffness at all (preload 0
and no drive given) has no kick instability: ``h_max = inf``.

The run's check (:func:`check_step`, :func:`stable_up_to`) asks more than one step: that the
step is stable at every overlap from ``delta0`` up to the run's largest. Inside the small-step
regime it is answered by a sufficient condition computed from half a step, with no eigenvalues and
no compiled code (:mod:`sim_backend.dem.stability_certificate`); the grid scan of the test above
is the fallback.

Long chains (N (J+1) > 256) are checked on windows of 32 cylinders whose end contacts hold fixed
neighbours (the stiffest boundary): the first and last windows and those around the stiffest block
mode and the lightest primary mass.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim_backend.dem import verdict_store
from sim_backend.dem.chain import Chain
from sim_backend.dem.drive import Drive
from sim_backend.dem.kernel import drift_coefficients
from sim_backend.dem.stability_certificate import certified, half_map
from sim_backend.dem.threads import one_blas_thread

__all__ = [
    "DEFAULT_OVERLAP_MARGIN",
    "StepLimit",
    "StepTooLargeError",
    "certificate_applies",
    "check_step",
    "contact_stiffness_N_per_m",
    "is_stable",
    "largest_stable_step",
    "range_key",
    "reference_overlap_m",
    "scan_range",
    "spectral_radius",
    "stable_up_to",
]

#: contacts are linearised at least at this multiple of the static overlap delta0
DEFAULT_OVERLAP_MARGIN = 4.0
#: rho(P) above 1 + this is unstable (stable eigenvalues sit on the unit circle to round-off)
STABILITY_TOL = 1.0e-6
_WINDOW = 32
_MAX_DOF = 256


class StepTooLargeError(ValueError):
    """An explicit integrator step that the chain's linearised step map says is unstable.

    Attributes: ``dt_s`` (the refused step, s), ``h_max_s`` (the largest stable step, s).
    """

    def __init__(self, message: str, dt_s: float, h_max_s: float) -> None:
        super().__init__(message)
        self.dt_s = dt_s
        self.h_max_s = h_max_s


@dataclass(frozen=True)
class StepLimit:
    """Result of :func:`largest_stable_step`.

    integrator: the splitting's name.
    h_max_s: largest step (s) of the small-step regime, below which every step is stable (inf:
        none unstable); see the module docstring.
    h_unstable_s: smallest step (s) found past it: unstable, or ``B`` not positive definite
        (inf: none).
    overlaps_m: contact overlaps (m) at which the contacts were linearised.
    stiffness_N_per_m: the matching contact stiffnesses (N/m).
    top_block_Hz: the stiffest block mode (Hz), integrated exactly by the drift.
    windows: number of chain windows checked (1: the whole chain).
    evaluations: spectral radii computed.
    """

    integrator: str
    h_max_s: float
    h_unstable_s: float
    overlaps_m: tuple[float, ...]
    stiffness_N_per_m: tuple[float, ...]
    top_block_Hz: float
    windows: int
    evaluations: int

    def describe(self, delta0_m: float) -> str:
        """One line: the limit and how it was found."""
        if delta0_m > 0:
            at = ", ".join(f"{d / delta0_m:.3g} delta0" for d in sorted(self.overlaps_m))
        else:
            at = ", ".join(f"{d * 1e6:.3g} um" for d in sorted(self.overlaps_m))
        return (
            f"largest stable step {self.h_max_s * 1e6:.4g} us for {self.integrator} "
            f"(spectral radius of the linearised step map, contacts at overlap {at}; "
            f"top block mode {self.top_block_Hz / 1e3:.4g} kHz)"
        )


def reference_overlap_m(
    chain: Chain, drives: Sequence[Drive] = (), margin: float = DEFAULT_OVERLAP_MARGIN
) -> float:
    """Overlap (m) at which to linearise the contacts for the stability check: ``margin``
    delta0, or more when a drive (with a factor 2) can press the contacts further."""
    d = margin * chain.delta0_m
    for drive in drives:
        if drive.kind == "displacement":
            d = max(d, chain.delta0_m + 2.0 * drive.amplitude)
        else:
            d = max(d, ((chain.f0_N + 2.0 * drive.amplitude) / chain.beta_c) ** (2.0 / 3.0))
    return d


def contact_stiffness_N_per_m(chain: Chain, overlap_m: float) -> float:
    """Tangent Hertz stiffness ``3/2 beta_c d^(1/2)`` (N/m) at overlap ``overlap_m`` (m)."""
    return 1.5 * chain.beta_c * math.sqrt(max(overlap_m, 0.0))


@dataclass(frozen=True)
class _Window:
    phi: NDArray[np.float64]  # [n, K] primary components of the block modes
    omega: NDArray[np.float64]  # [n, K] block mode angular frequencies (rad/s)
    left: bool  # a contact to the left of the first cylinder (wall or fixed neighbour)
    right: bool  # a contact to the right of the last cylinder


_WINDOW_CACHE: dict[int, tuple[Chain, list[_Window]]] = {}


def _windows(chain: Chain) -> list[_Window]:
    """The windows checked on ``chain`` (cached per chain object: the block modes cost about a
    millisecond, and a scan asks for them at every overlap)."""
    hit = _WINDOW_CACHE.get(id(chain))
    if hit is not None and hit[0] is chain:
        return hit[1]
    from sim_backend.dem.simulation import block_modes

    modes = block_modes(chain)
    N, K = modes.phi0.shape
    far = chain.far_end == "wall"
    if N * K <= _MAX_DOF:
        out = [_Window(modes.phi0, modes.omega, True, far)]
    else:
        w = min(_WINDOW, N)
        starts = {0, N - w}
        for centre in (int(np.argmax(modes.omega.max(axis=1))), int(np.argmin(chain.m0_kg))):
            starts.add(min(max(centre - w // 2, 0), N - w))
        out = []
        for s in sorted(starts):
            right = far if s + w == N else True
            out.append(_Window(modes.phi0[s : s + w], modes.omega[s : s + w], True, right))
    if len(_WINDOW_CACHE) > 16:
        _WINDOW_CACHE.clear()
    _WINDOW_CACHE[id(chain)] = (chain, out)  # the chain is held: its id is not reused meanwhile
    return out


def _contact_matrix(n: int, k: float, left: bool, right: bool) -> NDArray[np.float64]:
    kc = np.zeros((n, n))
    for j in range(1, n):
        kc[j - 1, j - 1] += k
        kc[j, j] += k
        kc[j - 1, j] -= k
        kc[j, j - 1] -= k
    if left:
        kc[0, 0] += k
    if right:
        kc[n - 1, n - 1] += k
    return kc


def _step_map(
    win: _Window, integrator: str, h: float, k: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The one-step map of the linearised (undamped) window at step ``h`` (s), contact stiffness
    ``k`` (N/m): ``(Q, P)``, each [D, 2D], the modal positions and momenta after one step as
    linear functions of the initial ``(q, p)``.

    A kick acts through the primary masses only: the window's primary displacements
    ``u = Phi^T q`` ([n]), the contact forces ``-Kc u``, spread back over the modes by ``Phi``;
    so a kick costs O(n K D), not the O(D^3) of the dense ``Phi^T Kc Phi`` product.
    """
    from sim_backend.dem.simulation import INTEGRATORS

    _, a_w, b_w = INTEGRATORS[integrator]
    phi = win.phi
    n, K = phi.shape
    D = n * K
    kc = _contact_matrix(n, k, win.left, win.right)
    om = win.omega.ravel()
    coef = {a: drift_coefficients(om, np.zeros_like(om), a * h) for a in set(a_w)}
    # the first drift applied to the identity: 2x2 blocks on the diagonal
    c = coef[a_w[0]]
    Q = np.zeros((D, 2 * D))
    P = np.zeros((D, 2 * D))
    i = np.arange(D)
    Q[i, i], Q[i, D + i], P[i, i], P[i, D + i] = c[:, 0], c[:, 1], c[:, 2], c[:, 3]
    for stage, b in enumerate(b_w):
        if stage > 0:
            c = coef[a_w[stage]]
            Q, P = c[:, 0:1] * Q + c[:, 1:2] * P, c[:, 2:3] * Q + c[:, 3:4] * P
        u = np.matmul(phi[:, None, :], Q.reshape(n, K, 2 * D))[:, 0, :]  # [n, 2D]
        f = (-(b * h)) * (kc @ u)
        P += (phi[:, :, None] * f[:, None, :]).reshape(D, 2 * D)
    c = coef[a_w[-1]]
    return c[:, 0:1] * Q + c[:, 1:2] * P, c[:, 2:3] * Q + c[:, 3:4] * P


def _palindromic(integrator: str) -> bool:
    from sim_backend.dem.simulation import INTEGRATORS

    _, a_w, b_w = INTEGRATORS[integrator]
    return tuple(a_w) == tuple(a_w[::-1]) and tuple(b_w) == tuple(b_w[::-1])


def _radius_from_cosines(c: NDArray[Any]) -> float:
    """Spectral radius of the step map from the eigenvalues ``c`` of its [D, D] position block:
    each ``c`` stands for the pair ``lambda = c +- sqrt(c^2 - 1)`` (module docstring)."""
    c = np.asarray(c, dtype=np.complex128)
    r = np.sqrt(c * c - 1.0)
    return float(max(np.abs(c + r).max(), np.abs(c - r).max(), 1.0))


def _window_radius(win: _Window, integrator: str, h: float, k: float) -> float:
    if not _palindromic(integrator):  # not time-reversible: the whole map's eigenvalues
        Q, P = _step_map(win, integrator, h, k)
        return float(np.abs(np.linalg.eigvals(np.vstack([Q, P]))).max())
    A, B = _position_blocks(win, integrator, h, np.array([k]))
    return _radius_from_blocks(A[0], B[0])


def _radius_from_blocks(A: NDArray[np.float64], B: NDArray[np.float64]) -> float:
    """Spectral radius of a time-reversible step map from its position blocks ``A``, ``B``
    ([D, D]): by the symmetric ``L^-1 A L`` when ``B = L L^T`` > 0, else by the eigenvalues
    of ``A`` (module docstring)."""
    Bs = 0.5 * (B + B.T)
    try:
        L = np.linalg.cholesky(Bs)
    except np.linalg.LinAlgError:
        return _radius_from_cosines(np.linalg.eigvals(A))
    S = np.linalg.solve(L, A @ L)  # L^-1 A L: symmetric (module docstring)
    return _radius_from_cosines(np.linalg.eigvalsh(0.5 * (S + S.T)))


#: stable means every ``c`` in [-C_TOL, C_TOL]: the ``c`` of ``rho = 1 + STABILITY_TOL``
_C_TOL = 0.5 * ((1.0 + STABILITY_TOL) + 1.0 / (1.0 + STABILITY_TOL))


def _position_blocks(
    win: _Window,
    integrator: str,
    h: float,
    stiffness: NDArray[np.float64],
    symmetric_b: bool = False,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Position blocks ``A``, ``B`` ([M, D, D]) of the step maps of a symmetric splitting for M
    contact stiffnesses (N/m), from half a step's map ``X``
    (:func:`sim_backend.dem.stability_certificate.half_map`): ``A = Xd^T Xa + Xb^T Xc``,
    ``B = 2 Xb^T Xd`` (``M = R X^-1 R X``). numpy and BLAS, nothing compiled (the compiled
    :func:`tests.dem.step_map.position_blocks`, built stage by stage, is the tests'
    independent reference). symmetric_b: ``B``'s symmetric part (symmetric to round-off)."""
    from sim_backend.dem.simulation import INTEGRATORS

    _, a_w, b_w = INTEGRATORS[integrator]
    D = win.phi.size
    A = np.empty((len(stiffness), D, D))
    B = np.empty((len(stiffness), D, D))
    for o, k in enumerate(stiffness):
        Q, P = half_map(win.phi, win.omega, win.left, win.right, a_w, b_w, h, float(k))
        Xa, Xb, Xc, Xd = Q[:, :D], Q[:, D:], P[:, :D], P[:, D:]
        A[o] = Xd.T @ Xa + Xb.T @ Xc
        B[o] = 2.0 * (Xb.T @ Xd)
        if symmetric_b:
            B[o] = 0.5 * (B[o] + B[o].T)
    return A, B


def _window_stable_many(
    win: _Window,
    integrator: str,
    h: float,
    stiffness: NDArray[np.float64],
    small_step: bool = False,
) -> list[bool]:
    """Whether ``rho <= 1 + STABILITY_TOL`` on one window, for each of M contact stiffnesses
    (N/m), by factorisations only where it can: the ``c`` lie in [-C, C] exactly when ``C B - A B``
    and ``C B + A B`` are positive definite (two Cholesky factorisations, LAPACK's ``dpotrf``),
    which also makes ``B = (C B - A B + C B + A B) / 2C`` positive definite, the premise of the
    equivalence; anything else (a factorisation that fails) is decided by the eigenvalues. The
    blocks come from half a step's map (:func:`_position_blocks`): nothing to compile or load, so
    a check that the certificate does not answer, or the search for the largest stable step behind
    a refusal, costs no compile on a fresh install (the compiled scan took 3 s to compile there).
    ``small_step``: also require ``B`` positive definite (the small-step regime of
    :func:`largest_stable_step`)."""
    if not _palindromic(integrator):
        return [_window_radius(win, integrator, h, k) <= 1.0 + STABILITY_TOL for k in stiffness]
    from scipy.linalg.lapack import dpotrf

    A, Bs = _position_blocks(win, integrator, h, np.asarray(stiffness), symmetric_b=True)
    out = []
    for o in range(A.shape[0]):
        ab = A[o] @ Bs[o]  # symmetric to round-off when B is
        cb = _C_TOL * Bs[o]
        ok = (
            dpotrf(np.subtract(cb, ab).T, lower=1, clean=0, overwrite_a=1)[1] == 0
            and dpotrf(np.add(cb, ab).T, lower=1, clean=0, overwrite_a=1)[1] == 0
        )
        if not ok and small_step and dpotrf(Bs[o].T, lower=1, clean=0, overwrite_a=0)[1] != 0:
            out.append(False)  # past the small-step regime
            continue
        out.append(ok or _radius_from_blocks(A[o], Bs[o]) <= 1.0 + STABILITY_TOL)
    return out


def _stable_many(
    chain: Chain,
    integrator: str,
    h: float,
    overlaps_m: Sequence[float],
    small_step: bool = False,
) -> list[bool]:
    """``spectral_radius(...) <= 1 + STABILITY_TOL`` at each overlap (m), all at once (one
    call per window for all of them), decided by :func:`_window_stable_many`."""
    if not overlaps_m:
        return []
    ks = np.array([contact_stiffness_N_per_m(chain, d) for d in overlaps_m])
    out = [True] * ks.size
    with one_blas_thread():
        for w in _windows(chain):
            for i, ok in enumerate(_window_stable_many(w, integrator, h, ks, small_step)):
                out[i] = out[i] and ok
    return out


def _stable_at(chain: Chain, integrator: str, h: float, overlap_m: float) -> bool:
    """``spectral_radius(...) <= 1 + STABILITY_TOL``, decided by :func:`_stable_many`."""
    return _stable_many(chain, integrator, h, [overlap_m])[0]


def spectral_radius(chain: Chain, integrator: str, h: float, overlap_m: float) -> float:
    """Largest ``|eigenvalue|`` of the linearised one-step map at step ``h`` (s), contacts
    linearised at ``overlap_m`` (m); the maximum over the checked windows of a long chain."""
    k = contact_stiffness_N_per_m(chain, overlap_m)
    with one_blas_thread():
        return max(_window_radius(w, integrator, h, k) for w in _windows(chain))


def _overlaps(chain: Chain, overlap_m: float | None) -> tuple[float, ...]:
    ref = reference_overlap_m(chain) if overlap_m is None else overlap_m
    # stiffest first: an unstable step usually fails there, so one eigenvalue problem decides
    out = sorted({d for d in (chain.delta0_m, ref) if d > 0}, reverse=True)
    return tuple(out)


_STABLE_CACHE: dict[tuple[str, str, float, tuple[float, ...]], bool] = {}


def is_stable(chain: Chain, integrator: str, h: float, overlap_m: float | None = None) -> bool:
    """Whether step ``h`` (s) is linearly stable with the contacts at ``delta0`` and at
    ``overlap_m`` (m; default :func:`reference_overlap_m` without drives). Cached."""
    overlaps = _overlaps(chain, overlap_m)
    key = (chain.spec.model_dump_json(), integrator, h, overlaps)
    hit = _STABLE_CACHE.get(key)
    if hit is None:
        hit = all(_stable_many(chain, integrator, h, overlaps))
        if len(_STABLE_CACHE) > 4096:
            _STABLE_CACHE.clear()
        _STABLE_CACHE[key] = hit
    return hit


_LIMIT_CACHE: dict[tuple[str, str, tuple[float, ...]], StepLimit] = {}


def largest_stable_step(
    chain: Chain, integrator: str, overlap_m: float | None = None, rel_tol: float = 2.0e-3
) -> StepLimit:
    """The largest stable step (s) of ``integrator`` on ``chain`` (see the module docstring),
    contacts linearised at ``delta0`` and ``overlap_m`` (m). Cached by chain content."""
    from sim_backend.dem.simulation import block_modes

    overlaps = _overlaps(chain, overlap_m)
    key = (chain.spec.model_dump_json(), integrator, overlaps)
    hit = _LIMIT_CACHE.get(key)
    if hit is not None:
        return hit
    w_top = float(block_modes(chain).omega.max())
    stiff = tuple(contact_stiffness_N_per_m(chain, d) for d in overlaps)
    n_win = len(_windows(chain))
    count = 0

    def stable(h: float) -> bool:  # stable, and B positive definite (the small-step regime)
        nonlocal count
        count += 1
        return all(_stable_many(chain, integrator, h, overlaps, small_step=True))

    inf = math.inf
    if not overlaps or max(stiff) == 0.0:
        lim = StepLimit(integrator, inf, inf, overlaps, stiff, w_top / (2 * math.pi), n_win, 0)
        _LIMIT_CACHE[key] = lim
        return lim
    h_lo = 0.25 * math.pi / w_top
    while not stable(h_lo):
        h_lo *= 0.5
        if h_lo < 1e-15:
            raise RuntimeError("no stable step found")
    h_hi = inf
    h = h_lo
    while h < 64.0 * math.pi / w_top:
        h *= 1.08
        if not stable(h):
            h_hi = h
            break
        h_lo = h
    if math.isfinite(h_hi):
        while h_hi - h_lo > rel_tol * h_lo:
            mid = 0.5 * (h_lo + h_hi)
            if stable(mid):
                h_lo = mid
            else:
                h_hi = mid
    else:
        h_lo = inf
    lim = StepLimit(integrator, h_lo, h_hi, overlaps, stiff, w_top / (2 * math.pi), n_win, count)
    if len(_LIMIT_CACHE) > 256:
        _LIMIT_CACHE.clear()
    _LIMIT_CACHE[key] = lim
    return lim


#: the certificate stands for every overlap below the one certified only for steps up to this
#: fraction of the small-step regime (``h w_top <= CERTIFIED_STEP_FRACTION pi``): nearer its
#: edge the stable overlaps of a graded chain need not form an interval (measured:
#: :mod:`sim_backend.dem.stability_certificate`), and the grid scan decides
CERTIFIED_STEP_FRACTION = 0.9
#: the certificate is tried first this many grid points above the one a run needs (overlap x 5.96,
#: stiffness x 2.44), so that a protocol's larger drives find their verdict in memory; where it
#: does not hold there, at the point needed
CERTIFIED_AHEAD = 8

#: overlaps of the stability range scan: ``delta0 * RANGE_RATIO^n`` (stiffness ratio 1.118)
RANGE_RATIO = 1.25


@dataclass
class _RangeVerdict:
    """What is known of one (chain, integrator, step): stable at every scanned overlap up to
    ``stable_to_m`` (m), and unstable at ``unstable_at_m`` (m; inf: none found yet)."""

    start_m: float
    stable_to_m: float = 0.0
    unstable_at_m: float = math.inf
    evaluations: int = 0


_RANGE_CACHE: dict[str, _RangeVerdict] = {}


def range_key(chain: Chain, integrator: str, h: float) -> str:
    """The key of a (chain, integrator, step) verdict: a digest of the chain's content, the
    integrator, ``repr(h)`` and ``MODES_VERSION`` (the user's cache and the shipped table)."""
    from sim_backend.dem.beam import MODES_VERSION

    text = f"{chain.spec.model_dump_json()}|{integrator}|{h!r}|modes={MODES_VERSION}"
    return hashlib.sha1(text.encode()).hexdigest()


def _disk_load(key: str) -> _RangeVerdict | None:
    """The verdict of ``key`` in the user's cache folder (:mod:`sim_backend.dem.verdict_store`)."""
    entry = verdict_store.load(key)
    try:
        if entry is None:
            return None
        return _RangeVerdict(float(entry[0]), float(entry[1]), float(entry[2]), 0)
    except (ValueError, TypeError, IndexError):
        return None


def _disk_store(key: str, v: _RangeVerdict) -> None:
    """Keep ``v`` in the user's cache folder (written when the process ends; best effort)."""
    unstable: float | str = v.unstable_at_m if math.isfinite(v.unstable_at_m) else "inf"
    verdict_store.store(key, [v.start_m, v.stable_to_m, unstable])


def _start_m(chain: Chain, overlap_m: float) -> float:
    return chain.delta0_m if chain.delta0_m > 0 else overlap_m / RANGE_RATIO**8


def _grid_at_or_above(start_m: float, overlap_m: float) -> float:
    """The first grid overlap ``start_m RANGE_RATIO^n`` (m) at or above ``overlap_m`` (m), by the
    same products as :func:`_extend`'s grid, so that the two agree to the bit."""
    d = start_m
    while d < overlap_m:
        d *= RANGE_RATIO
    return d


def certificate_applies(chain: Chain, integrator: str, h: float) -> bool:
    """Whether the stability certificate is tried for step ``h`` (s) of ``integrator``: a
    symmetric splitting, and ``h w_top`` at most ``CERTIFIED_STEP_FRACTION pi`` (else the grid
    scan decides at once)."""
    from sim_backend.dem.simulation import block_modes

    if not _palindromic(integrator):
        return False
    return h * float(block_modes(chain).omega.max()) <= CERTIFIED_STEP_FRACTION * math.pi


def _certified(chain: Chain, integrator: str, h: float, overlap_m: float) -> bool:
    """Whether step ``h`` (s) is certified stable with the contacts linearised at ``overlap_m``
    (m) on every checked window (:mod:`sim_backend.dem.stability_certificate`; palindromic
    splittings only), and so at every smaller overlap: a certificate, not a verdict (``False``
    means the grid must decide)."""
    if not certificate_applies(chain, integrator, h):
        return False
    from sim_backend.dem.simulation import INTEGRATORS

    _, a_w, b_w = INTEGRATORS[integrator]
    k = contact_stiffness_N_per_m(chain, overlap_m)
    with one_blas_thread():
        return all(
            certified(w.phi, w.omega, w.left, w.right, a_w, b_w, h, k) for w in _windows(chain)
        )


def _extend(v: _RangeVerdict, chain: Chain, integrator: str, h: float, overlap_m: float) -> bool:
    """Scan the grid points above what ``v`` knows up to the first at or above ``overlap_m``
    (all at once, one call per window), then in order up to the first unstable one; whether any
    was computed."""
    d = v.start_m if v.stable_to_m <= 0.0 else v.stable_to_m * RANGE_RATIO
    grid: list[float] = []
    while d < v.unstable_at_m and (not grid or grid[-1] < overlap_m):
        grid.append(d)
        d *= RANGE_RATIO
    if not grid:
        return False
    v.evaluations += len(grid)
    for d, ok in zip(grid, _stable_many(chain, integrator, h, grid), strict=True):
        if not ok:
            v.unstable_at_m = d
            break
        v.stable_to_m = d
    return True


def scan_range(chain: Chain, integrator: str, h: float, overlap_m: float) -> _RangeVerdict:
    """A fresh verdict of step ``h`` (s), scanned from ``delta0`` up to the grid point at or
    above ``overlap_m`` (m) or the first unstable one; no cache read or written (for the shipped
    table, :mod:`sim_backend.dem.shipped_stability`)."""
    v = _RangeVerdict(_start_m(chain, overlap_m))
    _extend(v, chain, integrator, h, overlap_m)
    return v


def _known(key: str) -> _RangeVerdict | None:
    """What the user's cache folder, else the shipped table, knows of ``key``."""
    v = _disk_load(key)
    if v is None:
        from sim_backend.dem.shipped_stability import lookup

        hit = lookup(key)
        if hit is not None:
            v = _RangeVerdict(*hit)
    return v


def _verdict(key: str, chain: Chain, overlap_m: float) -> _RangeVerdict:
    """What this process, the user's cache folder or the shipped table knows of ``key`` (kept in
    memory from now on), or a fresh verdict."""
    v = _RANGE_CACHE.get(key)
    if v is None:
        v = _known(key)
        if v is None:
            v = _RangeVerdict(_start_m(chain, overlap_m))
        if len(_RANGE_CACHE) > 256:
            _RANGE_CACHE.clear()
        _RANGE_CACHE[key] = v
    return v


def stable_up_to(chain: Chain, integrator: str, h: float, overlap_m: float) -> bool:
    """Whether step ``h`` (s) is linearly stable for every contact overlap from ``delta0`` up to
    ``overlap_m`` (m) (a run's contacts pass through every overlap up to their peak), judged up
    to ``top``, the grid point ``delta0 RANGE_RATIO^n`` at or above ``overlap_m``.

    First by one stability certificate (:func:`_certified`: half a step's map, two products and
    two Cholesky factorisations, under 1 ms on the default chain), which covers every overlap
    below the one certified: at the grid point ``CERTIFIED_AHEAD`` above ``top`` (so that the
    larger drives of the same protocol are answered from memory), else at ``top``; where neither
    holds (near or past the regime's edge, or a splitting that is not symmetric), by the scan of
    the grid points from ``delta0`` up to ``top`` (:func:`_extend`), stopping at the
    first unstable one. A grid point above ``overlap_m`` that
    is unstable falls back to the exact two-point check of :func:`is_stable` at ``overlap_m``.

    Computed once per (chain, integrator, step): the verdict grows lazily with the largest
    overlap asked for and is kept in memory and in the user's cache folder
    (:mod:`sim_backend.dem.verdict_store`), so the checks of a protocol's many drives, and of
    later runs, cost one certificate or scan; the shipped chains' verdicts at the shipped
    protocols' steps come with the package (:mod:`sim_backend.dem.shipped_stability`).
    """
    key = range_key(chain, integrator, h)
    v = _verdict(key, chain, overlap_m)
    if overlap_m <= v.stable_to_m:
        return True
    if overlap_m >= v.unstable_at_m:
        return False
    top = _grid_at_or_above(v.start_m, overlap_m)
    ahead = top
    for _ in range(CERTIFIED_AHEAD):
        ahead *= RANGE_RATIO
    tries = (ahead, top) if certificate_applies(chain, integrator, h) else ()
    for d in tries:
        if d >= v.unstable_at_m:
            continue
        v.evaluations += 1
        if _certified(chain, integrator, h, d):
            v.stable_to_m = d  # every grid point up to ``d`` at once
            _disk_store(key, v)
            return True
    if _extend(v, chain, integrator, h, overlap_m):
        _disk_store(key, v)
    if overlap_m <= v.stable_to_m:
        return True
    if v.unstable_at_m <= overlap_m:
        return False
    # unstable only at the grid point above: decide at the overlap itself (two-point check)
    return is_stable(chain, integrator, h, overlap_m)


def check_step(chain: Chain, integrator: str, h: float, drives: Sequence[Drive] = ()) -> None:
    """Raise :class:`StepTooLargeError` when step ``h`` (s) of ``integrator`` is linearly unstable
    on ``chain`` for contacts pressed by ``drives`` (see :func:`reference_overlap_m`): stable at
    every overlap from ``delta0`` to the reference overlap (:func:`stable_up_to`, once per chain
    and step)."""
    overlap = reference_overlap_m(chain, drives)
    if stable_up_to(chain, integrator, h, overlap):
        return
    lim = largest_stable_step(chain, integrator, overlap)
    raise StepTooLargeError(
        f"step {h * 1e6:.4g} us is unstable on this chain: {lim.describe(chain.delta0_m)}; "
        f"use dt <= {lim.h_max_s * 1e6:.4g} us",
        h,
        lim.h_max_s,
    )
