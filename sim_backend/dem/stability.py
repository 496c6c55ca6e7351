"""Stiff and extreme cases of the DEM integrators, each with a verdict (``biafc stability``).

Every case builds a chain variant, chooses the step (the integrator's default accuracy rule,
capped at half the largest linearly stable step of :mod:`sim_backend.dem.step_limit` for the
contacts pressed by the case's drives), runs, and checks: no NaN/Inf, and the energy balance
``(H_end - H_0 - W) / W`` within the case's tolerance (damping off where a clean balance is
needed). ``fast=True`` uses shorter windows (and, for J = 6, fewer cylinders) for the tests.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from instruments.burst import Burst
from sim_backend.dem.chain import Chain, build_chain
from sim_backend.dem.drive import Drive
from sim_backend.dem.simulation import (
    DEFAULT_INTEGRATOR,
    SimResult,
    StepTooLargeError,
    block_modes,
    default_step_s,
    simulate,
)
from sim_backend.dem.spec import BENCHMARK_DAMPING, ChainSpec, default_chain_spec
from sim_backend.dem.step_limit import largest_stable_step, reference_overlap_m

__all__ = ["CASES", "CaseResult", "adaptive_reference", "choose_step", "run_case"]

UNDAMPED = {"bending_mode_ratio": 0.0, "contact_dashpot_ratio": 0.0}
#: the damped variants of the extreme cases need the contact dashpot, which the default chain
#: has off since 2026-11-25: the benchmark chain's damping (dashpot ratio 0.005)
DASHPOT = BENCHMARK_DAMPING.model_dump()
RATE_HZ = 250.0e3


@dataclass
class CaseResult:
    """Outcome of one case.

    name, kind ("stiff" | "extreme"), stresses: what the case is about.
    integrator, dt_s: the step used (s); step_reason: why.
    max_abs_v_m_s: largest |velocity| recorded (m/s).
    energy_residual_rel: worst |H_end - H_0 - W| / W of the energy-balanced runs.
    tolerance: the bound on it. passed, reason: the verdict.
    window_s: simulated window (s). wall_s: run time (s).
    notes: further numbers (adaptive step statistics, open contacts, step-limit check).
    time_s [S], velocity [C, S] (m/s): one run's velocity field, for the figure.
    series: optional extra curve for the figure (label, x [k], y [k]).
    """

    name: str
    kind: str
    stresses: str
    integrator: str = DEFAULT_INTEGRATOR
    dt_s: float = math.nan
    step_reason: str = ""
    max_abs_v_m_s: float = math.nan
    energy_residual_rel: float = math.nan
    tolerance: float = math.nan
    passed: bool = False
    reason: str = ""
    window_s: float = math.nan
    wall_s: float = math.nan
    notes: list[str] = field(default_factory=list)
    time_s: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    velocity: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 0)))
    series: tuple[str, NDArray[np.float64], NDArray[np.float64]] | None = None


def _spec(**update: Any) -> ChainSpec:
    """The default chain with ``update`` applied, validated like a chain file."""
    data = default_chain_spec().model_dump()
    data.update(update)
    if "lengths" in update:
        for key in ("n_cylinders", "length_first", "length_last"):
            data[key] = None
    return ChainSpec.model_validate(data)


def _burst(direction: str, amp: float, kind: str = "displacement") -> Drive:
    f = 8.92e3 if direction == "ltr" else 6.63e3
    return Drive(direction, kind, amp, burst=Burst(f, 5.0))  # type: ignore[arg-type]


def choose_step(
    chain: Chain, drives: Sequence[Drive], integrator: str = DEFAULT_INTEGRATOR
) -> tuple[float, str]:
    """(step in s, why): the default accuracy rule, capped at half the largest stable step."""
    f_top = float(block_modes(chain).omega.max()) / (2.0 * math.pi)
    dt_acc = default_step_s(chain, integrator)
    overlap = reference_overlap_m(chain, drives)
    lim = largest_stable_step(chain, integrator, overlap)
    dt = min(dt_acc, 0.5 * lim.h_max_s)
    why = "accuracy rule" if dt == dt_acc else "0.5 x stability limit"
    at = (
        f"{overlap / chain.delta0_m:.3g} delta0"
        if chain.delta0_m > 0
        else f"{overlap * 1e6:.3g} um"
    )
    h_txt = f"{lim.h_max_s * 1e6:.3g} us" if math.isfinite(lim.h_max_s) else "inf"
    return dt, (
        f"{why}: default {dt_acc * 1e6:.3g} us (top block mode {f_top / 1e3:.0f} kHz), "
        f"h_max {h_txt} (contacts at {at})"
    )


def adaptive_reference(
    chain: Chain, drive: Drive, duration_s: float, t_eval: NDArray[np.float64],
    rtol: float = 1e-9, atol: float = 1e-15, min_step_s: float = 1e-10,
) -> tuple[NDArray[np.float64] | None, dict[str, Any]]:  # fmt: skip
    """scipy ``solve_ivp`` (DOP853) on :func:`reference.make_rhs`: primary velocities [N, S]
    (oriented as the kernel's output) at ``t_eval`` (s) and its step statistics (s): status,
    message, steps, nfev, min/median/max step, whether it went below ``min_step_s``."""
    from scipy.integrate import solve_ivp

    from sim_backend.dem.reference import make_rhs

    rhs, y0 = make_rhs(chain, drive)
    sol = solve_ivp(
        rhs, (0.0, duration_s), y0, method="DOP853", rtol=rtol, atol=atol, dense_output=True
    )
    steps = np.diff(sol.t)
    stats: dict[str, Any] = {
        "status": int(sol.status),
        "message": str(sol.message),
        "steps": int(steps.size),
        "nfev": int(sol.nfev),
        "min_step_s": float(steps.min()) if steps.size else math.nan,
        "median_step_s": float(np.median(steps)) if steps.size else math.nan,
        "max_step_s": float(steps.max()) if steps.size else math.nan,
        "hit_min_step": bool(sol.status != 0 or (steps.size and steps.min() < min_step_s)),
    }
    if sol.status != 0 or sol.sol is None:
        return None, stats
    n = chain.n * (chain.n_modes + 1)
    v = sol.sol(t_eval)[n : n + chain.n]
    if drive.direction == "rtl":
        v = -v[::-1]
    return v, stats


def _adaptive_note(stats: dict[str, Any]) -> str:
    return (
        f"adaptive DOP853 (rtol 1e-9): {stats['steps']} steps, {stats['nfev']} rhs calls, "
        f"step min/median/max {stats['min_step_s'] * 1e9:.3g}/{stats['median_step_s'] * 1e9:.3g}/"
        f"{stats['max_step_s'] * 1e9:.3g} ns, status {stats['status']} "
        f"({'hit min step' if stats['hit_min_step'] else 'above min step 0.1 ns'})"
    )


def _run(
    res: CaseResult, chain: Chain, drives: Sequence[Drive], duration_s: float, tol: float,
    cylinders: Sequence[int] | None = None, rate_Hz: float = RATE_HZ,
) -> SimResult:  # fmt: skip
    dt, why = choose_step(chain, drives, res.integrator)
    out = simulate(
        chain, drives, duration_s=duration_s, sample_rate_Hz=rate_Hz, dt_s=dt,
        integrator=res.integrator, cylinders=cylinders,
    )  # fmt: skip
    res.dt_s, res.step_reason = float(out.meta["dt_s"]), why
    res.window_s = duration_s
    vmax = float(np.nanmax(np.abs(out.velocity))) if out.meta["finite"] else math.inf
    res.max_abs_v_m_s = max(vmax, 0.0 if math.isnan(res.max_abs_v_m_s) else res.max_abs_v_m_s)
    if not out.meta["damped"]:
        e = float(np.max(np.abs(out.meta["energy_residual_rel"])))
        old = res.energy_residual_rel
        res.energy_residual_rel = e if math.isnan(old) else max(old, e)
    res.tolerance = tol
    if res.velocity.size == 0:
        res.time_s, res.velocity = out.time_s, out.velocity[0]
    return out


def _verdict(res: CaseResult, extra_fail: str = "") -> CaseResult:
    if not math.isfinite(res.max_abs_v_m_s):
        res.passed, res.reason = False, "NaN/Inf in the velocities"
    elif extra_fail:
        res.passed, res.reason = False, extra_fail
    elif not (res.energy_residual_rel <= res.tolerance):
        res.passed = False
        res.reason = f"energy residual {res.energy_residual_rel:.2g} > {res.tolerance:g}"
    else:
        res.passed = True
        res.reason = f"finite; energy residual {res.energy_residual_rel:.2g} <= {res.tolerance:g}"
    return res


# ---- the cases ---------------------------------------------------------------------------


def _six_modes(fast: bool, theory: str = "timoshenko") -> CaseResult:
    if theory == "timoshenko":
        res = CaseResult("six-modes", "stiff", "J = 6 resonators per cylinder (stiff block modes)")
    else:
        res = CaseResult(
            "six-modes-eb", "stiff", "J = 6, Euler-Bernoulli: resonators beyond 300 kHz"
        )
    upd: dict[str, Any] = {"n_modes": 6, "damping": UNDAMPED, "beam_theory": theory}
    if fast:
        upd.update(n_cylinders=8)
    chain = build_chain(_spec(**upd))
    f_res = chain.omega_res_rad_s.max() / (2 * math.pi)
    f_blk = block_modes(chain).omega.max() / (2 * math.pi)
    res.notes.append(f"top resonator {f_res / 1e3:.0f} kHz, top block mode {f_blk / 1e3:.0f} kHz")
    T = 2e-3 if fast else 5e-3
    d = [_burst("ltr", 2 * chain.delta0_m), _burst("rtl", 2 * chain.f0_N, "force")]
    out = _run(res, chain, d, T, 1e-4)
    T_ref = 0.5e-3 if fast else 1e-3
    t = out.time_s[out.time_s <= T_ref]
    v_ref, stats = adaptive_reference(chain, d[0], T_ref, t)
    res.notes.append(_adaptive_note(stats))
    fail = ""
    if v_ref is not None:
        err = float(np.abs(out.velocity[0][:, : t.size] - v_ref).max() / np.abs(v_ref).max())
        res.notes.append(f"kernel vs adaptive over {T_ref * 1e3:g} ms: max rel error {err:.2g}")
        if err > 1e-4:
            fail = f"kernel vs adaptive reference {err:.2g} > 1e-4"
    return _verdict(res, fail)


def _both_ways_2_delta0(res: CaseResult, chain: Chain, fast: bool) -> CaseResult:
    """Run an undamped stiff case: a 2 delta0 burst in each direction, energy within 1e-4."""
    d = [_burst("ltr", 2 * chain.delta0_m), _burst("rtl", 2 * chain.delta0_m)]
    _run(res, chain, d, 2e-3 if fast else 5e-3, 1e-4)
    return _verdict(res)


def _stiff_contact(fast: bool) -> CaseResult:
    res = CaseResult("stiff-contact", "stiff", "5x stiffer contacts (K x 5: beta_c x 5^1.5)")
    chain = build_chain(_spec(contact_stiffness_factor=5.0**1.5, damping=UNDAMPED))
    res.notes.append(f"K = {chain.K_lin:.3g} N/m, delta0 = {chain.delta0_m * 1e6:.3g} um")
    return _both_ways_2_delta0(res, chain, fast)


def _mixed_scale(fast: bool) -> CaseResult:
    res = CaseResult("mixed-scale", "stiff", "cylinder #16 10x heavier (density x 10)")
    chain = build_chain(_spec(density_factors={16: 10.0}, damping=UNDAMPED))
    res.notes.append(f"masses #15/#16: {chain.mass_kg[14]:.3g}/{chain.mass_kg[15]:.3g} kg")
    return _both_ways_2_delta0(res, chain, fast)


def _drive_50(fast: bool) -> CaseResult:
    res = CaseResult("drive-50-delta0", "extreme", "drive 50 delta0: contacts open for long")
    chain = build_chain(_spec(damping=UNDAMPED))
    T = 2e-3 if fast else 5e-3
    d = [_burst("ltr", 50 * chain.delta0_m)]
    out = _run(res, chain, d, T, 1e-3)
    u = out.displacement[0]
    gaps = chain.delta0_m + u[:-1] - u[1:]
    active = np.abs(out.velocity[0][1:]).max(axis=1) > 1e-3 * res.max_abs_v_m_s
    open_frac = float(np.mean(gaps[active] < 0)) if active.any() else 0.0
    res.notes.append(f"contacts reached by the wave open {100 * open_frac:.0f} % of the samples")
    damped = build_chain(_spec(damping=DASHPOT))
    outd = _run(res, damped, d, T, 1e-3)
    gain, work = float(outd.meta["energy_gain_J"][0]), float(outd.meta["input_work_J"][0])
    res.notes.append(f"damped run: energy kept {gain / work:.3f} of the input work (<= 1)")
    return _verdict(res, "" if gain <= work else "damped run created energy")


def _zero_preload(fast: bool) -> CaseResult:
    res = CaseResult("zero-preload", "extreme", "F0 = 0 (sonic vacuum) and F0 = 1 mN")
    T = 2e-3 if fast else 5e-3
    for f0 in ("0 N", "1 mN"):
        chain = build_chain(_spec(preload=f0, damping=UNDAMPED))
        _run(res, chain, [_burst("ltr", 1e-6)], T, 1e-3)
    tiny = build_chain(_spec(preload="1 mN", damping=DASHPOT))  # chi = c / F0 large but finite
    chi = float(tiny.hunt_crossley_chi_s_per_m().max())
    outd = simulate(tiny, [_burst("ltr", 1e-6)], duration_s=T, sample_rate_Hz=RATE_HZ)
    res.notes.append(f"F0 = 1 mN damped: chi = {chi:.3g} s/m, finite = {outd.meta['finite']}")
    return _verdict(res, "" if outd.meta["finite"] else "damped tiny preload diverged")


def _undamped_1s(fast: bool) -> CaseResult:
    res = CaseResult("undamped-1s", "extreme", "no damping over 1 s (energy drift bounded)")
    chain = build_chain(_spec(damping=UNDAMPED))
    d = [_burst("ltr", chain.delta0_m)]
    windows = (0.02, 0.05, 0.1) if fast else (0.25, 0.5, 1.0)
    resid = []
    for T in windows:
        out = _run(res, chain, d, T, 1e-4, rate_Hz=50e3)
        resid.append(float(out.meta["energy_residual_rel"][0]))
    res.series = ("energy residual vs window (s)", np.array(windows), np.array(resid))
    res.notes.append(
        "residual at " + ", ".join(f"{T:g} s: {r:.2g}" for T, r in zip(windows, resid, strict=True))
    )
    return _verdict(res)


def _chain_1000(fast: bool) -> CaseResult:
    res = CaseResult("chain-1000", "extreme", "1000 cylinders (90 -> 110 mm in 0.5 mm steps)")
    lengths = np.round(np.linspace(90.0, 110.0, 1000) * 2.0) / 2.0
    chain = build_chain(_spec(lengths=[f"{x:g} mm" for x in lengths], damping=UNDAMPED))
    d = [_burst("ltr", 2 * chain.delta0_m), _burst("rtl", 2 * chain.delta0_m)]
    _run(res, chain, d, 2e-3 if fast else 10e-3, 1e-4, cylinders=range(1, 1001, 10))
    return _verdict(res)


def _single(fast: bool) -> CaseResult:
    res = CaseResult("single-cylinder", "extreme", "N = 1 (wall on both sides)")
    chain = build_chain(_spec(lengths=["100 mm"], damping=UNDAMPED))
    d = [_burst("ltr", chain.delta0_m), _burst("rtl", chain.f0_N, "force")]
    _run(res, chain, d, 2e-3 if fast else 5e-3, 1e-4)
    return _verdict(res)


def _missing_contact(fast: bool) -> CaseResult:
    res = CaseResult("missing-contact", "extreme", "1 um gap at contact #16-#17, F0 = 0")
    chain = build_chain(_spec(preload="0 N", contact_gaps={16: "1 um"}, damping=UNDAMPED))
    d = [_burst("ltr", 2e-6)]
    T = 3e-3 if fast else 10e-3
    out = _run(res, chain, d, T, 1e-3)
    e = np.sum(out.velocity[0] ** 2, axis=1)
    res.notes.append(f"energy beyond the gap (#17..#31): {e[16:].sum() / e.sum():.2g} of sum v^2")
    T_ref = 1e-3 if fast else 2e-3
    t = out.time_s[out.time_s <= T_ref]
    v_ref, stats = adaptive_reference(chain, d[0], T_ref, t)
    res.notes.append(_adaptive_note(stats))
    if v_ref is not None:
        err = float(np.abs(out.velocity[0][:, : t.size] - v_ref).max() / np.abs(v_ref).max())
        res.notes.append(f"kernel vs adaptive over {T_ref * 1e3:g} ms: max rel error {err:.2g}")
    return _verdict(res)


def _step_limit(fast: bool) -> CaseResult:
    res = CaseResult("step-limit", "stiff", "strang just below / above its largest stable step")
    res.integrator = "strang"
    chain = build_chain(_spec(damping=UNDAMPED))
    lim = largest_stable_step(chain, "strang", chain.delta0_m)
    d = [_burst("ltr", 0.01 * chain.delta0_m)]
    T = 30e-3  # the unstable mode starts from round-off: it needs a few thousand steps
    grow: dict[float, float] = {}
    for f in (0.99, 1.01):
        h = f * lim.h_max_s
        out = simulate(chain, d, duration_s=T, sample_rate_Hz=1.0 / h, dt_s=h,
                       integrator="strang", refuse_unstable=False)  # fmt: skip
        v = np.abs(out.velocity[0])
        n = max(1, int(1e-3 / h))
        late = float(np.max(v[:, -n:])) if np.all(np.isfinite(v[:, -n:])) else math.inf
        grow[f] = late / float(np.max(v[:, :n]))
        if f == 0.99:
            res.time_s, res.velocity, res.dt_s = out.time_s, out.velocity[0], h
            res.max_abs_v_m_s = float(v.max())
            res.energy_residual_rel = abs(float(out.meta["energy_residual_rel"][0]))
    res.step_reason = (
        f"predicted h_max {lim.h_max_s * 1e6:.4g} us (linearised at delta0); "
        f"runs at 0.99 and 1.01 h_max"
    )
    res.window_s, res.tolerance = T, 1e-2
    res.notes.append(
        f"late/early max|v|: 0.99 h_max -> {grow[0.99]:.3g}, 1.01 h_max -> {grow[1.01]:.3g}"
    )
    try:
        simulate(chain, d, duration_s=1e-4, integrator="strang", dt_s=1.05 * lim.h_max_s,
                 sample_rate_Hz=1.0 / (1.05 * lim.h_max_s))  # fmt: skip
        refused = "not refused"
    except StepTooLargeError as exc:
        refused = f"refused: {exc}"
    res.notes.append(f"simulate(dt = 1.05 h_max) {refused}")
    ok = grow[0.99] < 10.0 and grow[1.01] > 100.0 and refused.startswith("refused")
    return _verdict(res, "" if ok else "the step limit does not separate stable / unstable")


#: name -> (kind, what it stresses, runner(fast) -> CaseResult)
CASES: dict[str, Callable[[bool], CaseResult]] = {
    "six-modes": _six_modes,
    "six-modes-eb": lambda fast: _six_modes(fast, "euler-bernoulli"),
    "stiff-contact": _stiff_contact,
    "mixed-scale": _mixed_scale,
    "step-limit": _step_limit,
    "drive-50-delta0": _drive_50,
    "zero-preload": _zero_preload,
    "undamped-1s": _undamped_1s,
    "chain-1000": _chain_1000,
    "single-cylinder": _single,
    "missing-contact": _missing_contact,
}


def run_case(name: str, fast: bool = False) -> CaseResult:
    """Run the case ``name`` of :data:`CASES` (``fast``: test windows) and time it."""
    t0 = time.perf_counter()
    res = CASES[name](fast)
    res.wall_s = time.perf_counter() - t0
    return res
