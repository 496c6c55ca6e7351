"""Error against run time of the integrators on an :class:`AccuracyScene` (``biafc accuracy``).

Every method runs over a ladder of steps (the compiled fixed-step splittings of
:data:`~sim_backend.dem.simulation.INTEGRATORS`) or of tolerances (``scipy.integrate.solve_ivp``
DOP853 and RK45 on :func:`sim_backend.dem.reference.make_rhs`). Each run is timed, its steps and
right-hand-side evaluations (contact-force kicks for the splittings, ``nfev`` for solve_ivp)
counted, and its velocity compared with the scene's converged reference
(:func:`sim_backend.dem.converged.converged_reference`): relative L2 over the window
(:func:`sim_backend.dem.errors.rel_l2`) at the driven cylinder, at the far cylinder and at the
worst cylinder. The observed order of a fixed-step method is the least-squares slope of
log(worst error) against log(step) over its asymptotic range (errors below 1e-2 and above ten
times the reference's own last change).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from sim_backend.dem.accuracy_scenes import BUILTIN_SCENES, AccuracyScene
from sim_backend.dem.converged import ConvergedReference, converged_reference
from sim_backend.dem.errors import rel_l2
from sim_backend.dem.reference import make_rhs
from sim_backend.dem.simulation import DEFAULT_INTEGRATOR, INTEGRATORS

__all__ = [
    "FULL_LADDERS",
    "QUICK_LADDERS",
    "Measurement",
    "SceneReport",
    "measure_fixed",
    "measure_scipy",
    "observed_order",
    "run_accuracy",
]

#: suffix of a compiled splitting run with Heun kicks (``simulate(dashpot_kick="heun3")``)
HEUN = "+heun3"
#: method -> ladder: steps (s) for the compiled splittings, rtol for solve_ivp methods
FULL_LADDERS: dict[str, tuple[float, ...]] = {
    DEFAULT_INTEGRATOR: (4e-6, 2e-6, 1e-6, 0.5e-6, 0.25e-6),
    f"{DEFAULT_INTEGRATOR}{HEUN}": (4e-6, 2e-6, 1e-6, 0.5e-6, 0.25e-6),
    "yoshida4": (2e-6, 1e-6, 0.5e-6, 0.25e-6),
    "suzuki4": (2e-6, 1e-6, 0.5e-6, 0.25e-6),
    "strang": (0.8e-6, 0.4e-6, 0.2e-6, 0.1e-6, 0.05e-6),
    "DOP853": (1e-5, 1e-7, 1e-9, 1e-11),
    "RK45": (1e-4, 1e-5, 1e-6, 1e-7),
}
#: the same methods on short ladders (tests, ``--quick``)
QUICK_LADDERS: dict[str, tuple[float, ...]] = {
    DEFAULT_INTEGRATOR: (4e-6, 2e-6, 1e-6),
    f"{DEFAULT_INTEGRATOR}{HEUN}": (2e-6, 1e-6),
    "yoshida4": (2e-6, 1e-6),
    "suzuki4": (2e-6, 1e-6),
    "strang": (0.4e-6, 0.2e-6, 0.1e-6),
    "DOP853": (1e-6, 1e-8),
    "RK45": (1e-4, 1e-5),
}
SCIPY_METHODS = ("DOP853", "RK45")
#: errors above this are pre-asymptotic and left out of the order fit
PRE_ASYMPTOTIC_REL = 1e-2


@dataclass(frozen=True)
class Measurement:
    """One run of one method. ``setting``: the step (s, fixed-step methods) or ``rtol``;
    errors: relative L2 over the window, driven / far / worst cylinder."""

    method: str
    setting_name: str  # "dt_s" | "rtol"
    setting: float
    wall_s: float
    steps: int
    rhs_evals: int
    err_driven: float
    err_far: float
    err_worst: float


@dataclass
class SceneReport:
    """Everything measured on one scene; ``orders``: observed order per fixed-step method
    (``None`` when fewer than two points lie in the asymptotic range); ``local_orders``: the
    slope between each pair of neighbouring steps of the ladder."""

    scene: str
    description: str
    duration_s: float
    sample_rate_Hz: float
    amplitude: float
    amplitude_units: str
    reference: dict[str, Any]
    measurements: list[Measurement] = field(default_factory=list)
    orders: dict[str, float | None] = field(default_factory=dict)
    local_orders: dict[str, list[float]] = field(default_factory=dict)
    nominal_orders: dict[str, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["measurements"] = [asdict(m) for m in self.measurements]
        return out


def _errors(
    scene: AccuracyScene, v: NDArray[np.float64], ref: ConvergedReference
) -> tuple[float, float, float]:
    """(driven, far, worst) relative L2 errors of ``v`` ``[N, S]`` (cylinder order)."""
    err = rel_l2(v[None], ref.velocity[None])[0]
    i_drv, i_far = scene.driven_far()
    return float(err[i_drv]), float(err[i_far]), float(err.max())


def _timed_best(fn: Any, min_total_s: float = 0.3, max_repeats: int = 3) -> tuple[Any, float]:
    """Run ``fn()``; repeat short runs (best of up to ``max_repeats``) for a stable wall time.
    When the compiled kernel is not loaded yet, one untimed call first: loading it (or compiling
    it, 1-15 s) is not the method's run time."""
    from sim_backend.dem.kernel_cache import kernel_loaded

    if not kernel_loaded():
        fn()
    best = math.inf
    out = None
    spent = 0.0
    for _ in range(max_repeats):
        t0 = time.perf_counter()
        out = fn()
        dt = time.perf_counter() - t0
        best = min(best, dt)
        spent += dt
        if spent >= min_total_s:
            break
    return out, best


def measure_fixed(
    scene: AccuracyScene, ref: ConvergedReference, integrator: str, dt_s: float
) -> Measurement:
    """Run the compiled ``integrator`` (a key of ``INTEGRATORS``, with :data:`HEUN` appended for
    Heun kicks) at step ``dt_s`` (s) on the scene and measure it."""
    name, kick = _splitting(integrator)
    res, wall = _timed_best(lambda: scene.simulate(name, dt_s, dashpot_kick=kick))
    steps = int(res.meta["substeps_per_sample"]) * (scene.n_samples - 1)
    kicks = len(INTEGRATORS[name][2]) * steps
    e = _errors(scene, res.velocity[0], ref)
    return Measurement(integrator, "dt_s", float(res.meta["dt_s"]), wall, steps, kicks, *e)


def _splitting(method: str) -> tuple[str, Literal["midpoint", "heun3"]]:
    """(integrator, dashpot kick) of a compiled method name."""
    if method.endswith(HEUN):
        return method[: -len(HEUN)], "heun3"
    return method, "midpoint"


def measure_scipy(
    scene: AccuracyScene, ref: ConvergedReference, method: str, rtol: float
) -> Measurement:
    """Run ``solve_ivp(method)`` at ``rtol`` on the scene (``atol`` = rtol times the scale of
    each state: the drive's displacement amplitude for positions, that times ``2 pi f`` for
    velocities) and measure it."""
    chain, drive = scene.chain(), scene.drive()
    rhs, y0 = make_rhs(chain, drive)
    n = chain.n
    dof = y0.size // 2
    x_scale = scene.amplitude if scene.kind == "displacement" else scene.amplitude / chain.K_lin
    scale = np.concatenate(
        [np.full(dof, x_scale), np.full(dof, x_scale * 2.0 * math.pi * scene.f_center_Hz)]
    )
    t_eval = np.arange(scene.n_samples) / scene.sample_rate_Hz
    t0 = time.perf_counter()
    sol = solve_ivp(
        rhs, (0.0, float(t_eval[-1])), y0, method=method, rtol=rtol, atol=rtol * scale,
        dense_output=True,
    )  # fmt: skip
    if not sol.success:
        raise RuntimeError(f"solve_ivp {method} at rtol {rtol:g} failed: {sol.message}")
    v = np.asarray(sol.sol(t_eval)[dof : dof + n], dtype=np.float64)
    wall = time.perf_counter() - t0
    if scene.direction == "rtl":
        v = -v[::-1]
    e = _errors(scene, v, ref)
    return Measurement(method, "rtol", rtol, wall, len(sol.t) - 1, int(sol.nfev), *e)


def observed_order(steps_s: list[float], errors: list[float], floor_rel: float) -> float | None:
    """Slope of log(error) vs log(step) over the points with ``10 floor_rel < error <
    PRE_ASYMPTOTIC_REL``; ``None`` with fewer than two such points."""
    pts = [
        (math.log(h), math.log(e))
        for h, e in zip(steps_s, errors, strict=True)
        if 10.0 * floor_rel < e < PRE_ASYMPTOTIC_REL and h > 0
    ]
    if len({p[0] for p in pts}) < 2:
        return None
    x = np.array([p[0] for p in pts])
    y = np.array([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def accuracy_runs(quick: bool = False, methods: list[str] | None = None) -> int:
    """How many steps :func:`run_accuracy` takes on one scene: the reference, then one per
    setting of every ladder (for a progress display)."""
    ladders = QUICK_LADDERS if quick else FULL_LADDERS
    names = list(ladders) if methods is None else methods
    return 1 + sum(len(ladders[m]) for m in names if m in ladders)


def run_accuracy(
    scene: AccuracyScene,
    *,
    quick: bool = False,
    methods: list[str] | None = None,
    use_cache: bool = True,
    on_step: Callable[[str], None] | None = None,
) -> SceneReport:
    """Measure every method of the ladders (``quick``: the short ones) on ``scene``;
    ``on_step(what)`` is called after the reference and after each setting (progress)."""
    step = on_step or (lambda what: None)
    ladders = QUICK_LADDERS if quick else FULL_LADDERS
    names = list(ladders) if methods is None else methods
    unknown = [m for m in names if m not in ladders]
    if unknown:
        raise ValueError(f"unknown method(s) {unknown}; choose from {list(ladders)}")
    if quick:
        ref = converged_reference(scene, dt0_s=0.125e-6, min_dt_s=62.5e-9, use_cache=use_cache)
    else:
        ref = converged_reference(scene, use_cache=use_cache)
    step(f"{scene.name}: reference")
    report = SceneReport(
        scene=scene.name,
        description=BUILTIN_SCENES.get(scene.name, "custom scene"),
        duration_s=scene.duration_s,
        sample_rate_Hz=scene.sample_rate_Hz,
        amplitude=scene.amplitude,
        amplitude_units="m" if scene.kind == "displacement" else "N",
        reference=ref.summary(),
    )
    for name in names:
        rows: list[Measurement] = []
        for setting in ladders[name]:
            if name in SCIPY_METHODS:
                rows.append(measure_scipy(scene, ref, name, setting))
            else:
                rows.append(measure_fixed(scene, ref, name, setting))
            step(f"{scene.name}: {name} at {setting:.3g}")
        report.measurements.extend(rows)
        if name not in SCIPY_METHODS:
            report.nominal_orders[name] = INTEGRATORS[_splitting(name)[0]][0]
            report.orders[name] = observed_order(
                [m.setting for m in rows], [m.err_worst for m in rows], ref.change_rel
            )
            report.local_orders[name] = [
                math.log(a.err_worst / b.err_worst) / math.log(a.setting / b.setting)
                for a, b in itertools.pairwise(rows)
            ]
    return report
