"""Modal (state-space) solution of the linearised chain: exact for the linear ODE, no time steps.

``M x'' + C x' + K x = b a(t) + b_c a'(t)`` (:func:`sim_backend.dem.reference.linear_matrices`;
``b_c`` is the drive wall's dashpot, ``a`` the drive in m or N). With ``z = [x, x']``,
``z' = A z + B a + B_c a'`` and ``A = V diag(lambda) V^-1``, the modal coordinates
``xi = V^-1 z - g_c a`` (``g_c = V^-1 B_c``) obey ``xi' = lambda xi + (g + lambda g_c) a``: no
derivative of the drive is needed. While the drive is on, ``xi`` is advanced by the exact
first-order-hold recursion on a fine grid (step <= ``FINE_STEP_S``: the drive is taken linear
between fine samples, relative error about ``(2 pi f h)^2 / 12`` < 1e-4 below 15 kHz); after the
drive it decays exactly, ``xi(t) = xi(t_end) exp(lambda (t - t_end))``. A drive's response is
computed once per drive shape at unit amplitude and scaled (the chain is linear), so an amplitude
sweep costs one solution per shape.

Not for a force drive on a chain with a free far end (a rigid-body mode: ``A`` is defective).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import eig, solve

from sim_backend.dem.chain import Chain
from sim_backend.dem.drive import Drive
from sim_backend.dem.reference import linear_matrices
from sim_backend.dem.threads import one_blas_thread

__all__ = ["FINE_STEP_S", "LinearResponse", "drive_end_s", "linear_response"]

#: largest step (s) of the first-order-hold recursion while the drive is on
FINE_STEP_S = 0.25e-6


@dataclass(frozen=True)
class LinearResponse:
    """Output of :func:`linear_response` (same conventions as ``SimResult``).

    time_s: [S] sample times (s). velocity, displacement: [R, C, S] (m/s, m) or ``None`` when not
    requested; drive: [R, S] (m or N) or ``None``. cylinders: [C] 1-based.
    max_overlap_change_m: [R] largest change of any contact's overlap over the window (m), from
    every cylinder's displacement (the check of the linearisation).
    """

    time_s: NDArray[np.float64]
    velocity: NDArray[np.float64] | None
    displacement: NDArray[np.float64] | None
    drive: NDArray[np.float64] | None
    cylinders: NDArray[np.int32]
    max_overlap_change_m: NDArray[np.float64]


def drive_end_s(drive: Drive) -> float:
    """Time (s from the trigger) after which the drive is zero."""
    if drive.burst is not None:
        return drive.delay_s + drive.burst.duration_s
    assert drive.waveform is not None
    samples, rate = drive.waveform
    return drive.delay_s + (np.asarray(samples).size - 1) / rate


def _foh_weights(lam: NDArray[np.complex128], h: float) -> tuple[NDArray[np.complex128], ...]:
    """(exp(lam h), w0, w1): ``xi1 = e xi0 + w0 a0 + w1 a1`` per unit modal input, input linear
    over the step. Series for small ``|lam h|``."""
    z = lam * h
    e = np.exp(z)
    small = np.abs(z) < 1e-4
    zs = np.where(small, 1.0, z)
    e1 = np.where(small, h * (1 + z / 2 + z**2 / 6), (e - 1.0) / np.where(small, 1.0, lam))
    w1 = np.where(small, h * (0.5 + z / 6 + z**2 / 24), (e1 - h) / zs)
    return e, e1 - w1, w1


@dataclass(frozen=True)
class _Modes:
    """Eigen-decomposition of the state matrix, conjugate pairs folded: ``lam`` [P] (rad/s),
    ``V`` [2D, P], ``g``, ``gc`` [P] modal drive and drive-dashpot inputs, ``weight`` [P] (1 for
    a real eigenvalue, 2 for one of a pair with Im > 0: z = Re(V (weight * xi)))."""

    lam: NDArray[np.complex128]
    V: NDArray[np.complex128]
    g: NDArray[np.complex128]
    gc: NDArray[np.complex128]
    weight: NDArray[np.float64]


_MODES: dict[tuple[int, str, str], tuple[Chain, _Modes]] = {}


def _modes(chain: Chain, direction: str, kind: str) -> _Modes:
    """State-space modes of the oriented linearised chain (cached per chain, direction, kind)."""
    key = (id(chain), direction, kind)
    hit = _MODES.get(key)
    if hit is not None and hit[0] is chain:
        return hit[1]
    M, K, C, b = linear_matrices(chain, direction, kind)
    D = M.shape[0]
    dash = chain.contact_dashpot_Ns_per_m()
    if direction == "rtl":
        dash = dash[::-1]
    bc = np.zeros(D)
    if kind == "displacement":
        bc[0] = dash[0]
    minv = 1.0 / np.diag(M)
    A = np.zeros((2 * D, 2 * D))
    A[:D, D:] = np.eye(D)
    A[D:, :D] = -minv[:, None] * K
    A[D:, D:] = -minv[:, None] * C
    B = np.concatenate([np.zeros(D), minv * b])
    Bc = np.concatenate([np.zeros(D), minv * bc])
    with one_blas_thread():
        lam, V = eig(A)
        g, gc = solve(V, np.stack([B, Bc], axis=1)).T
    scale = np.maximum(np.abs(lam), 1.0)
    keep = lam.imag >= -1e-9 * scale
    pair = lam.imag > 1e-9 * scale
    modes = _Modes(lam[keep], V[:, keep], g[keep], gc[keep], np.where(pair[keep], 2.0, 1.0))
    if len(_MODES) > 32:
        _MODES.clear()
    _MODES[key] = (chain, modes)
    return modes


def _unit_response(
    chain: Chain, drive: Drive, t_s: NDArray[np.float64], rows: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Oriented state rows ``rows`` of z = [x, x'] at ``t_s`` for the drive at unit amplitude
    ([len(rows), S]) and every contact's overlap change ([N+1, S], m)."""
    md = _modes(chain, drive.direction, drive.kind)
    lam, V, gc = md.lam, md.V, md.gc
    N = chain.n
    gin = md.g + lam * gc
    # fine grid: n_up steps per sample period, up to the first sample at or after the drive's end
    period = float(t_s[1] - t_s[0]) if t_s.size > 1 else FINE_STEP_S
    n_up = max(1, math.ceil(period / FINE_STEP_S - 1e-9))
    h = period / n_up
    s_last = min(math.ceil(drive_end_s(drive) / period - 1e-9), t_s.size - 1)
    n_fine = s_last * n_up + 1
    t_fine = np.arange(n_fine, dtype=np.float64) * h
    unit = Drive(drive.direction, drive.kind, 1.0, drive.burst, drive.waveform, drive.delay_s)
    a_fine = unit.value(t_fine)
    e, w0, w1 = _foh_weights(lam, h)
    # xi on the fine grid, one first-order recursion per mode (xi(0) = 0: the chain at rest);
    # scipy.signal here, not at import: it took 0.7-0.8 s, which the window paid as it opened
    # (it imports this module with the model overlay) and never used
    from scipy.signal import lfilter

    xi_fine = np.empty((lam.size, n_fine), dtype=np.complex128)
    for k in range(lam.size):
        xi_fine[k] = gin[k] * lfilter([w1[k], w0[k]], [1.0, -e[k]], a_fine)
    xi = np.empty((lam.size, t_s.size), dtype=np.complex128)
    xi[:, : s_last + 1] = xi_fine[:, ::n_up]
    # after the drive: exact free decay
    xi[:, s_last + 1 :] = xi_fine[:, -1:] * np.exp(np.outer(lam, t_s[s_last + 1 :] - t_fine[-1]))
    a_s = unit.value(t_s)
    modal = (xi + np.outer(gc, a_s)) * md.weight[:, None]
    all_rows = np.concatenate([rows, np.arange(N)])
    z_all = np.real(V[all_rows] @ modal)
    z_rows, u = z_all[: rows.size], z_all[rows.size :]
    # overlap changes: wall-#1, #i-#(i+1), #N-wall (oriented), every cylinder's displacement
    ov = np.empty((N + 1, t_s.size))
    ov[0] = (a_s - u[0]) if drive.kind == "displacement" else -u[0]
    ov[1:N] = u[:-1] - u[1:]
    ov[N] = u[-1] if chain.far_end == "wall" else 0.0
    return z_rows, ov


def linear_response(
    chain: Chain,
    drives: Sequence[Drive],
    *,
    duration_s: float,
    sample_rate_Hz: float,
    cylinders: Sequence[int] | None = None,
    record: Collection[str] = ("velocity", "displacement", "drive"),
) -> LinearResponse:
    """Response of the linearised chain (contacts at ``chain.K_lin``, linearised dashpots) to
    each drive, sampled like :func:`sim_backend.dem.simulation.simulate` (S = floor(T rate) + 1
    samples; velocity/displacement along the chain axis, positive from #1 towards #N).

    Raises ``ValueError`` for a force drive on a chain with a free far end (rigid-body mode).
    """
    if chain.far_end == "free" and any(d.kind == "force" for d in drives):
        raise ValueError("linear_response: a force drive with a free far end has a rigid mode")
    n_samples = math.floor(duration_s * sample_rate_Hz + 1e-9) + 1
    t_s = np.arange(n_samples) / sample_rate_Hz
    idx = (
        np.arange(chain.n, dtype=np.int64)
        if cylinders is None
        else np.asarray(list(cylinders), dtype=np.int64) - 1
    )
    if idx.size == 0 or idx.min() < 0 or idx.max() >= chain.n:
        raise ValueError(f"cylinders must be 1-based numbers in 1..{chain.n}")
    R, Cn = len(drives), idx.size
    D = chain.n * (chain.n_modes + 1)
    want_v, want_u = "velocity" in record, "displacement" in record
    vel = np.empty((R, Cn, n_samples)) if want_v else None
    disp = np.empty((R, Cn, n_samples)) if want_u else None
    drv = np.empty((R, n_samples)) if "drive" in record else None
    max_ov = np.empty(R)
    cache: dict[tuple[object, ...], tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
    for r, d in enumerate(drives):
        oriented = idx if d.direction == "ltr" else chain.n - 1 - idx
        rows = np.concatenate([oriented, D + oriented])
        shape_key = (d.direction, d.kind, d.burst, id(d.waveform), d.delay_s)
        if shape_key not in cache:
            cache[shape_key] = _unit_response(chain, d, t_s, rows)
        z, ov = cache[shape_key]
        sign = d.amplitude * (1.0 if d.direction == "ltr" else -1.0)
        if disp is not None:
            disp[r] = sign * z[:Cn]
        if vel is not None:
            vel[r] = sign * z[Cn:]
        if drv is not None:
            drv[r] = d.value(t_s)
        max_ov[r] = d.amplitude * float(np.abs(ov).max())
    return LinearResponse(
        time_s=t_s,
        velocity=vel,
        displacement=disp,
        drive=drv,
        cylinders=(idx + 1).astype(np.int32),
        max_overlap_change_m=max_ov,
    )
