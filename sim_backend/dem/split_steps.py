"""Steps split at the drives' breakpoints, for the compiled kernel (:mod:`sim_backend.dem.kernel`).

An analytic burst (:mod:`instruments.burst`) is a Gaussian shifted so that its envelope is 0 at
both ends of its window, where it reaches 0 with a slope: a moving wall's velocity jumps at the
burst's start and end (``t = delay`` and ``t = delay + T``), and so does the force of the
actuator contact's Hunt-Crossley dashpot, which acts on that velocity. A splitting samples the
forces at its kick times, so a jump between two kicks of a step leaves an O(h) error that depends
on where the jump falls (docs/performance.md, section 3). These instants are known before the
run: a step ``[t, t + h)`` holding one strictly inside (more than :data:`BREAK_TOL` h from both
ends) is done as consecutive sub-steps of the same splitting between them (lengths ``h1, h2,
...``, drift coefficients computed for those lengths here), each evaluating the drive by the
formula of its own side of the breakpoint. The samples stay on the fixed grid.

The steps of one chunk are shared by its lanes. A sample holding breakpoints is therefore run once
per group of lanes with the same breakpoints in it (one pass each, from the sample's start state),
and each lane keeps the pass of its own breakpoints: a drive's result does not depend on the batch
around it, and a sample without breakpoints is computed as before, bit for bit.

A pass's schedule is the kernel's: entry ``kk`` is a drift (kind ``sk_drift[kk]``, an index into
the chunk's drift table, of length ``sk_dt[kk]`` s), then, unless it ends a pass, a kick of
``sk_h[kk]`` s with the drive evaluated on the side of ``sk_side[kk]`` (a time inside the
sub-step; NaN in a whole step: the drive at the kick's time); ``sk_flag[kk]`` bit 0 marks a
pass's first drift, bit 1 its last. The passes of a sample are concatenated.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from sim_backend.dem.kernel_cache import install_cache_locator

install_cache_locator()  # before the decorators below: compiled code to the user's cache folder

__all__ = [
    "BREAK_TOL",
    "drift_into",
    "find_breakpoints",
    "keep_lanes",
    "lane_groups",
    "load_state",
    "pass_drifts",
    "pass_entries",
    "save_state",
    "split_samples",
    "split_schedule",
]

#: a breakpoint closer than this fraction of a step to a step's boundary is taken as on it (the
#: step is not split; the error left is about this fraction of the one a split removes)
BREAK_TOL = 1e-7
#: breakpoints of one drive (its burst's start and end)
MAX_PER_LANE = 2


@numba.njit(cache=True)
def drift_into(
    out: NDArray[np.float64],  # [N, K, 4]
    omega: NDArray[np.float64],  # [N, K] rad/s
    zeta: NDArray[np.float64],  # [N, K]
    length: float,  # s
) -> None:
    """``out`` = :func:`sim_backend.dem.kernel.drift_coefficients` ``(omega, zeta, length)``:
    the same formula, in scalar code."""
    N, K = omega.shape
    for i in range(N):
        for k in range(K):
            w = omega[i, k]
            if w <= 0.0:
                out[i, k, 0] = 1.0
                out[i, k, 1] = length
                out[i, k, 2] = 0.0
                out[i, k, 3] = 1.0
                continue
            z = zeta[i, k]
            wd = w * math.sqrt(1.0 - z * z)
            e = math.exp(-z * w * length)
            c = math.cos(wd * length)
            s = math.sin(wd * length)
            out[i, k, 0] = e * (c + z * w / wd * s)
            out[i, k, 1] = e * s / wd
            out[i, k, 2] = -e * w * w / wd * s
            out[i, k, 3] = e * (c - z * w / wd * s)


@numba.njit(cache=True)
def find_breakpoints(
    lanes: NDArray[np.int64],  # [W] trajectory of each lane (-1: padding)
    src: NDArray[np.int64],  # [R] 0 = analytic burst, 1 = table
    prm: NDArray[np.float64],  # [R, 8] the drives' parameters (kernel.drive_value)
    period: float,  # s between samples
    h: float,  # step (s)
    n_sub: int,  # steps per sample
    n_samples: int,
    bp_n: NDArray[np.int64],  # [W] out: breakpoints of each lane strictly inside a step
    bp_smp: NDArray[np.int64],  # [W, 2] out: their sample (the step's sample)
    bp_st: NDArray[np.int64],  # [W, 2] out: their step in that sample
    bp_y: NDArray[np.float64],  # [W, 2] out: their time after that step's start (s)
) -> None:
    """The breakpoints of every lane's drive that fall strictly inside a step, in time order:
    an analytic burst with a nonzero amplitude has two, ``delay`` and ``delay + T`` (tables,
    whose slope jumps at every sample, have none here). The step's start is taken on the grid,
    ``sample / rate + step h``."""
    W = lanes.size
    tol = BREAK_TOL * h
    for b in range(W):
        bp_n[b] = 0
        r = lanes[b]
        if r < 0 or src[r] != 0 or prm[r, 0] == 0.0:
            continue
        for j in range(MAX_PER_LANE):
            tb = prm[r, 6] + (prm[r, 2] if j == 1 else 0.0)
            if tb <= 0.0 or tb >= (n_samples - 1) * period:
                continue
            s = math.floor(tb / period)
            x = tb - s * period
            st = math.floor(x / h)
            if st < 0 or st >= n_sub:
                continue
            y = x - st * h
            if y <= tol or y >= h - tol:
                continue
            n = bp_n[b]
            if n > 0 and bp_smp[b, n - 1] == s and bp_st[b, n - 1] == st:
                if y - bp_y[b, n - 1] <= tol:
                    continue
            bp_smp[b, n] = s
            bp_st[b, n] = st
            bp_y[b, n] = y
            bp_n[b] = n + 1


@numba.njit(cache=True)
def lane_groups(
    s: int,
    bp_n: NDArray[np.int64],
    bp_smp: NDArray[np.int64],
    bp_st: NDArray[np.int64],
    bp_y: NDArray[np.float64],
    group: NDArray[np.int64],  # [W] out: group of each lane
) -> int:
    """Group the lanes by their breakpoints in sample ``s`` (lanes with none form a group too);
    returns the number of groups, numbered in the order of their first lane."""
    W = bp_n.size
    n_groups = 0
    for b in range(W):
        group[b] = -1
        for a in range(b):
            if _same_breaks(s, a, b, bp_n, bp_smp, bp_st, bp_y):
                group[b] = group[a]
                break
        if group[b] < 0:
            group[b] = n_groups
            n_groups += 1
    return n_groups


@numba.njit(cache=True)
def _same_breaks(
    s: int,
    a: int,
    b: int,
    bp_n: NDArray[np.int64],
    bp_smp: NDArray[np.int64],
    bp_st: NDArray[np.int64],
    bp_y: NDArray[np.float64],
) -> bool:
    """Whether lanes ``a`` and ``b`` have the same breakpoints in sample ``s``."""
    ja = 0
    jb = 0
    while True:
        while ja < bp_n[a] and bp_smp[a, ja] != s:
            ja += 1
        while jb < bp_n[b] and bp_smp[b, jb] != s:
            jb += 1
        end_a = ja >= bp_n[a]
        end_b = jb >= bp_n[b]
        if end_a or end_b:
            return end_a and end_b
        if bp_st[a, ja] != bp_st[b, jb] or bp_y[a, ja] != bp_y[b, jb]:
            return False
        ja += 1
        jb += 1


@numba.njit(cache=True)
def split_samples(
    bp_n: NDArray[np.int64],
    bp_smp: NDArray[np.int64],
    bp_st: NDArray[np.int64],
    bp_y: NDArray[np.float64],
) -> tuple[NDArray[np.int64], int]:
    """(the samples holding a breakpoint of some lane, ascending; the most passes one of them
    needs). At most ``2 W`` samples, sorted by insertion (``np.unique``'s sort and array
    checks would be compiled into the kernel's chunk body, four times: module docstring of
    :mod:`sim_backend.dem.kernel`)."""
    W = bp_n.size
    cand = np.empty(W * MAX_PER_LANE, dtype=np.int64)
    n = 0
    for b in range(W):
        for j in range(bp_n[b]):
            x = bp_smp[b, j]
            at = n  # insert x, keeping cand[:n] ascending and without repeats
            while at > 0 and cand[at - 1] > x:
                at -= 1
            if at > 0 and cand[at - 1] == x:
                continue
            for i in range(n, at, -1):
                cand[i] = cand[i - 1]
            cand[at] = x
            n += 1
    group = np.empty(W, dtype=np.int64)
    most = 0
    for j in range(n):
        n_groups = lane_groups(int(cand[j]), bp_n, bp_smp, bp_st, bp_y, group)
        most = max(most, n_groups)
    return cand[:n], most


@numba.njit(cache=True)
def pass_drifts(m: int) -> int:
    """Most drifts of new lengths in one pass of :func:`split_schedule` (``m`` kicks a step):
    <= 2 breakpoints split <= 2 steps into <= 4 sub-steps of ``m`` drifts each, and the drift
    after each split step."""
    return MAX_PER_LANE * 2 * m + MAX_PER_LANE


@numba.njit(cache=True)
def pass_entries(n_kicks: int, m: int) -> int:
    """Most entries of one pass of :func:`split_schedule`: a whole sample's ``n_kicks + 1`` and
    ``m`` more per breakpoint."""
    return n_kicks + 1 + MAX_PER_LANE * m


@numba.njit(cache=True)
def split_schedule(
    s: int,
    group: NDArray[np.int64],  # [W] from lane_groups
    n_groups: int,
    bp_n: NDArray[np.int64],
    bp_smp: NDArray[np.int64],
    bp_st: NDArray[np.int64],
    bp_y: NDArray[np.float64],
    period: float,
    h: float,
    n_sub: int,
    kick_b: NDArray[np.float64],  # [m] kick weights
    drift_a: NDArray[np.float64],  # [m + 1] drift weights
    kick_drift: NDArray[np.int64],  # [n_sub m + 1] the whole sample's schedule (kernel)
    kick_dt: NDArray[np.float64],
    kick_h: NDArray[np.float64],
    omega: NDArray[np.float64],  # [N, K] oriented
    zeta: NDArray[np.float64],  # [N, K]
    co: NDArray[np.float64],  # [nd + slots, N, K, 4]: kinds nd.. are written here
    nd: int,
    sk_drift: NDArray[np.int64],  # out, see the module docstring
    sk_dt: NDArray[np.float64],
    sk_h: NDArray[np.float64],
    sk_side: NDArray[np.float64],
    sk_flag: NDArray[np.int64],
) -> int:
    """The passes of sample ``s``, one per lane group, concatenated; returns their entries.

    Whole steps keep the kernel's drifts and kicks (the merged last/first drift between two
    whole steps included); a split step's sub-steps of length ``L`` drift by ``a_k L`` and kick
    by ``b_k L``, the last drift of one merged with the first of the next (``a_m L1 + a_0 L2``,
    also across a step boundary), with drift coefficients computed for those lengths."""
    m = kick_b.size
    nk = 0
    slot = nd
    for g in range(n_groups):
        rep = 0
        while group[rep] != g:
            rep += 1
        j = 0
        while j < bp_n[rep] and bp_smp[rep, j] != s:
            j += 1
        pend = 0.0  # the last drift of the previous piece (s); 0 at the sample's start
        prev_whole = True  # the previous piece was a whole step (or the sample's start)
        first = True
        for step in range(n_sub):
            lo = 0.0
            while True:
                hi = h
                if j < bp_n[rep] and bp_smp[rep, j] == s and bp_st[rep, j] == step:
                    hi = bp_y[rep, j]
                    j += 1
                length = hi - lo
                whole = lo == 0.0 and hi == h
                side = s * period + step * h + 0.5 * (lo + hi)
                for stage in range(m):
                    ks = step * m + stage  # the same drift and kick in a whole sample
                    if whole and (stage > 0 or prev_whole):
                        sk_drift[nk] = kick_drift[ks]
                        sk_dt[nk] = kick_dt[ks]
                        sk_h[nk] = kick_h[ks]
                        sk_side[nk] = math.nan
                    else:
                        dt = drift_a[stage] * length + (pend if stage == 0 else 0.0)
                        drift_into(co[slot], omega, zeta, dt)
                        sk_drift[nk] = slot
                        slot += 1
                        sk_dt[nk] = dt
                        sk_h[nk] = kick_b[stage] * length
                        sk_side[nk] = math.nan if whole else side
                    sk_flag[nk] = 1 if first else 0
                    first = False
                    nk += 1
                pend = drift_a[m] * length
                prev_whole = whole
                lo = hi
                if hi == h:
                    break
        if prev_whole:
            sk_drift[nk] = kick_drift[n_sub * m]
            sk_dt[nk] = kick_dt[n_sub * m]
        else:
            drift_into(co[slot], omega, zeta, pend)
            sk_drift[nk] = slot
            slot += 1
            sk_dt[nk] = pend
        sk_h[nk] = 0.0
        sk_side[nk] = math.nan
        sk_flag[nk] = 2
        nk += 1
    return nk


@numba.njit(cache=True)
def save_state(
    keep: NDArray[np.float64],  # [2 N K W + N W + W]
    q: NDArray[np.float64],  # [N K W] flat
    p: NDArray[np.float64],
    force: NDArray[np.float64],  # [N W] flat
    work: NDArray[np.float64],  # [W]
) -> None:
    """``keep`` = (q, p, force, work) of a chunk (element loops: a slice assignment compiles
    its shape check and error message into the kernel's chunk body)."""
    nq = q.size
    nf = force.size
    for j in range(nq):
        keep[j] = q[j]
        keep[nq + j] = p[j]
    for j in range(nf):
        keep[2 * nq + j] = force[j]
    for j in range(work.size):
        keep[2 * nq + nf + j] = work[j]


@numba.njit(cache=True)
def load_state(
    keep: NDArray[np.float64],
    q: NDArray[np.float64],
    p: NDArray[np.float64],
    force: NDArray[np.float64],
    work: NDArray[np.float64],
) -> None:
    """(q, p, force, work) of a chunk = ``keep`` (element loops, as :func:`save_state`)."""
    nq = q.size
    nf = force.size
    for j in range(nq):
        q[j] = keep[j]
        p[j] = keep[nq + j]
    for j in range(nf):
        force[j] = keep[2 * nq + j]
    for j in range(work.size):
        work[j] = keep[2 * nq + nf + j]


@numba.njit(cache=True)
def keep_lanes(
    res: NDArray[np.float64],  # [2 N K W + N W + W], the layout of save_state
    q: NDArray[np.float64],
    p: NDArray[np.float64],
    force: NDArray[np.float64],
    work: NDArray[np.float64],
    group: NDArray[np.int64],  # [W]
    g: int,
) -> None:
    """Copy the state of the lanes of group ``g`` (the last index of every array is the lane)
    into ``res``."""
    W = work.size
    nq = q.size
    nf = force.size
    for j in range(nq):
        if group[j % W] == g:
            res[j] = q[j]
            res[nq + j] = p[j]
    for j in range(nf):
        if group[j % W] == g:
            res[2 * nq + j] = force[j]
    for b in range(W):
        if group[b] == g:
            res[2 * nq + nf + b] = work[b]
