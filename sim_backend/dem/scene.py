"""A scene (chain + drives + what is recorded) decides the model it needs and says what it dropped.

:func:`plan_scene` returns a :class:`ScenePlan` with one :class:`Decision` per aspect:

- ``modes``: resonators far above the drive's spectrum are condensed into ``m0``
  (:mod:`sim_backend.dem.condense`). Bound: relative apparent-mass error
  ``eps = max_i sum_dropped (m_ij/m_i) r^2/(1 - r^2)``, ``r = f_max/f_ij``, over ``[0, f_max]``;
  ``f_max`` = top of the drive spectrum (burst centre + 4 spectral sigmas) times the harmonics the
  amplitude can make (1 in the linear regime, ``tolerances.harmonics`` otherwise). What it does
  to a run (measured, default and J = 6 chains, docs/scenes.md): the per-cylinder energy
  ``sum_t v^2`` moves by <= ``ENERGY_PROFILE_FACTOR * eps`` of its maximum; the velocity waveform
  drifts in phase, relative L2 error <= ``pi f_c T eps`` over a window T (measured 5-20x below).
- ``nonlinearity``: the predicted dynamic overlap change ``rho`` (in units of delta0: the drive
  amplitude for a displacement drive, ``F / K`` for a force drive) sets the linearisation error:
  the Hertz force's quadratic term is ``rho / 4`` of the linear one, so the velocity error is
  about ``rho / 4`` (measured 0.05-0.17 rho); the displacement picks up the contacts' rectified
  mean drift, error about ``3 rho`` (measured 2.5 rho). Below ``tolerances.linear_error`` the
  scene uses the exact modal solution of the linearised chain
  (:mod:`sim_backend.dem.linear_response`); after the run the realised overlap change (every
  contact, from the linear solution) is checked, and the nonlinear kernel is run instead if it
  is too large.
- ``time``: the kernel stops once every drive is over and the energy left in the chain is at most
  ``tolerances.stop_energy_fraction`` of the input work (damped chains only). The record is then
  truncated at the stop (no sample is invented); every cylinder's velocity after the stop is
  bounded by ``sqrt(2 E_left / m0)`` (the chain is passive once the drive is over), reported as
  ``meta["velocity_bound_after_stop_m_per_s"]``.
- ``output``: only the recorded cylinders and quantities are allocated and computed.

:func:`run_scene` executes a plan; :func:`full_plan` is the plan that keeps everything (the full
model, :func:`sim_backend.dem.simulation.simulate` unchanged) for comparisons.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from sim_backend.dem.chain import Chain
from sim_backend.dem.condense import (
    condensation_error,
    condense_chain,
    drive_top_frequency_Hz,
    modes_to_keep,
)
from sim_backend.dem.drive import Drive
from sim_backend.dem.linear_response import linear_response
from sim_backend.dem.simulation import (
    DEFAULT_SAMPLE_RATE_HZ,
    RECORDABLE,
    default_step_s,
    simulate,
)

__all__ = [
    "ENERGY_PROFILE_FACTOR",
    "Decision",
    "Scene",
    "ScenePlan",
    "SceneResult",
    "SceneTolerances",
    "full_plan",
    "linearisation_error",
    "overlap_ratio",
    "plan_scene",
    "run_scene",
]

#: measured ratio bound: per-cylinder energy profile error / apparent-mass error bound eps
ENERGY_PROFILE_FACTOR = 2.0


@dataclass(frozen=True)
class Scene:
    """What is simulated and recorded.

    chain: the built chain. drives: R drives. duration_s: window (s). sample_rate_Hz: record rate.
    cylinders: 1-based numbers recorded (``None``: all). record: quantities kept, a subset of
    ``("velocity", "displacement", "drive")``.
    """

    chain: Chain
    drives: tuple[Drive, ...]
    duration_s: float
    sample_rate_Hz: float = DEFAULT_SAMPLE_RATE_HZ
    cylinders: tuple[int, ...] | None = None
    record: tuple[str, ...] = RECORDABLE

    def __post_init__(self) -> None:
        if len(self.drives) == 0:
            raise ValueError("a scene needs at least one drive")
        if not (math.isfinite(self.duration_s) and self.duration_s > 0):
            raise ValueError(f"duration_s must be > 0, got {self.duration_s!r}")
        if not (math.isfinite(self.sample_rate_Hz) and self.sample_rate_Hz > 0):
            raise ValueError(f"sample_rate_Hz must be > 0, got {self.sample_rate_Hz!r}")
        bad = [q for q in self.record if q not in RECORDABLE]
        if bad or not self.record:
            raise ValueError(f"record: choose one or more of {RECORDABLE}, got {self.record!r}")
        if self.cylinders is not None and (
            not self.cylinders or min(self.cylinders) < 1 or max(self.cylinders) > self.chain.n
        ):
            raise ValueError(f"cylinders must be 1-based numbers in 1..{self.chain.n}")

    @property
    def n_samples(self) -> int:
        """S = floor(duration * rate) + 1."""
        return math.floor(self.duration_s * self.sample_rate_Hz + 1e-9) + 1

    @property
    def n_recorded(self) -> int:
        """Number of recorded cylinders C."""
        return self.chain.n if self.cylinders is None else len(self.cylinders)


@dataclass(frozen=True)
class SceneTolerances:
    """What the planner may drop (all dimensionless).

    mass_error: largest relative apparent-mass error of condensing resonators (default 1e-3, the
        size of the 3-mode cell's own band-edge error against the continuum).
    linear_error: largest predicted relative error of the linearised solution in a recorded
        quantity (velocity ~ rho/4, displacement ~ 3 rho).
    stop_energy_fraction: stop once the energy left is at most this fraction of the input work.
    harmonics: harmonics of the drive's top frequency counted in the nonlinear regime.
    n_sigma: spectral widths of a burst above its centre that count as its band.
    """

    mass_error: float = 1.0e-3
    linear_error: float = 1.0e-2
    stop_energy_fraction: float = 1.0e-3
    harmonics: int = 2
    n_sigma: float = 4.0


@dataclass(frozen=True)
class Decision:
    """One decision of a plan.

    aspect: ``"modes"``, ``"nonlinearity"``, ``"time"`` or ``"output"``. reduced: True when
    something was dropped. action: what is done (short). reason: why. error_bound: the stated
    bound or estimate (dimensionless, relative) or ``None``. saving: estimated saving (text).
    """

    aspect: str
    reduced: bool
    action: str
    reason: str
    error_bound: float | None = None
    saving: str = ""

    def line(self) -> str:
        """One line for ``--explain``."""
        state = "DROPPED" if self.reduced else "kept"
        bound = "" if self.error_bound is None else f"; error bound {self.error_bound:.2g}"
        saving = f"; saving: {self.saving}" if self.saving else ""
        return f"{self.aspect}: {state}: {self.action} ({self.reason}{bound}{saving})"


@dataclass(frozen=True)
class ScenePlan:
    """The model a scene needs: the chain to run (possibly condensed), the solver, the stop rule,
    the outputs, and the decisions that led there."""

    scene: Scene
    chain: Chain
    solver: Literal["nonlinear", "linear-modal"]
    stop_energy_fraction: float | None
    record: tuple[str, ...]
    decisions: tuple[Decision, ...]
    tolerances: SceneTolerances = field(default_factory=SceneTolerances)
    overlap_ratio: float = 0.0

    def explain(self) -> str:
        """The decisions, one per line, after a header naming the scene."""
        sc = self.scene
        head = (
            f"scene: {len(sc.drives)} drive(s), {sc.duration_s * 1e3:g} ms at "
            f"{sc.sample_rate_Hz / 1e3:g} kS/s, {sc.n_recorded} of {sc.chain.n} cylinders, "
            f"{'+'.join(sc.record)}; predicted overlap change {self.overlap_ratio:.3g} delta0"
        )
        return "\n".join([head, *(d.line() for d in self.decisions)])

    def as_dict(self) -> dict[str, Any]:
        """Plain data (for a run file's attributes)."""
        return {
            "solver": self.solver,
            "n_modes": self.chain.n_modes,
            "stop_energy_fraction": self.stop_energy_fraction,
            "record": list(self.record),
            "overlap_ratio": self.overlap_ratio,
            "decisions": [asdict(d) for d in self.decisions],
        }


@dataclass(frozen=True)
class SceneResult:
    """Output of :func:`run_scene`: like ``SimResult``, with ``None`` for unrequested quantities.

    time_s: [S'] (S' <= S when the run stopped early). velocity, displacement: [R, C, S'] or
    ``None``; drive: [R, S'] or ``None``. cylinders: [C] 1-based. meta: solver, n_modes, wall_s,
    the plan (``plan``), stop information, realised overlap change, fallback.
    """

    time_s: NDArray[np.float64]
    velocity: NDArray[np.float64] | None
    displacement: NDArray[np.float64] | None
    drive: NDArray[np.float64] | None
    cylinders: NDArray[np.int32]
    meta: dict[str, Any]


def overlap_ratio(chain: Chain, drive: Drive) -> float:
    """Predicted largest dynamic overlap change over delta0 (dimensionless): the wall's travel
    (displacement drive, m) or ``F / K_lin`` (force drive, N) divided by ``chain.delta0_m``;
    infinite for a chain without preload (delta0 = 0: every drive opens its contacts)."""
    if not (chain.delta0_m > 0 and chain.K_lin > 0):
        return math.inf if drive.amplitude > 0 else 0.0
    travel_m = drive.amplitude if drive.kind == "displacement" else drive.amplitude / chain.K_lin
    return travel_m / chain.delta0_m


def linearisation_error(rho: float, record: Sequence[str]) -> float:
    """Predicted relative error of the linearised chain in the recorded quantities at overlap
    ratio ``rho``: ``rho / 4`` for velocity, ``3 rho`` for displacement, 0 for the drive."""
    per = {"velocity": rho / 4.0, "displacement": 3.0 * rho, "drive": 0.0}
    return max(per[q] for q in record)


def _kernel_cost(chain: Chain) -> float:
    """Relative cost of one simulated second: (J + 1) block modes per cylinder over the step."""
    return chain.n * (chain.n_modes + 1) / default_step_s(chain)


def _plan_modes(scene: Scene, tol: SceneTolerances, linear_regime: bool) -> tuple[Chain, Decision]:
    chain = scene.chain
    J = chain.n_modes
    f_top = max(drive_top_frequency_Hz(d, tol.n_sigma) for d in scene.drives)
    harm = 1 if linear_regime else tol.harmonics
    f_max = harm * f_top
    keep = modes_to_keep(chain, f_max, tol.mass_error)
    band = f"drive band to {f_max / 1e3:.3g} kHz" + ("" if harm == 1 else f" ({harm} harmonics)")
    if keep == J:
        nxt = condensation_error(chain, J - 1, f_max) if J > 1 else math.inf
        f_lo = float(chain.omega_res_rad_s[:, J - 1].min()) / (2.0 * math.pi)
        reason = (
            f"{band}; condensing mode {J} (from {f_lo / 1e3:.3g} kHz) would err "
            f"{nxt:.2g} of the apparent mass > {tol.mass_error:.2g} allowed"
        )
        return chain, Decision("modes", False, f"all {J} resonators per cylinder", reason)
    reduced = condense_chain(chain, keep)
    eps = condensation_error(chain, keep, f_max)
    f_lo = float(chain.omega_res_rad_s[:, keep].min()) / (2.0 * math.pi)
    saving = 1.0 - _kernel_cost(reduced) / _kernel_cost(chain)
    reason = (
        f"{band}; modes {keep + 1}..{J} start at {f_lo / 1e3:.3g} kHz; relative apparent-mass "
        f"error <= {eps:.2g} over the band (energy profile <= {ENERGY_PROFILE_FACTOR * eps:.2g})"
    )
    action = f"modes {keep + 1}..{J} condensed into m0, {keep} of {J} kept"
    return reduced, Decision("modes", True, action, reason, eps, f"~{saving:.0%} kernel time")


def plan_scene(
    scene: Scene, tolerances: SceneTolerances | None = None, *, reduce: bool = True
) -> ScenePlan:
    """Decide the model ``scene`` needs. ``reduce=False`` gives :func:`full_plan`."""
    tol = tolerances or SceneTolerances()
    if not reduce:
        return full_plan(scene)
    chain = scene.chain
    rho = max(overlap_ratio(chain, d) for d in scene.drives)
    err_lin = linearisation_error(rho, scene.record)
    rigid = chain.far_end == "free" and any(d.kind == "force" for d in scene.drives)
    linear = err_lin <= tol.linear_error and not rigid
    run_chain, modes = _plan_modes(scene, tol, linear)
    if linear:
        shapes = len({(d.direction, d.kind, d.burst, id(d.waveform), d.delay_s)
                      for d in scene.drives})  # fmt: skip
        nonlin = Decision(
            "nonlinearity", True, "linearised contacts, exact modal solution",
            f"overlap change {rho:.2g} delta0: predicted error {err_lin:.2g} <= "
            f"{tol.linear_error:.2g}; checked after the run on every contact",
            err_lin, f"{shapes} modal solution(s) for {len(scene.drives)} drive(s), no steps",
        )  # fmt: skip
    else:
        why = (
            "a force drive with a free far end has a rigid-body mode"
            if rigid
            else f"overlap change {rho:.2g} delta0: linearised error {err_lin:.2g} > "
            f"{tol.linear_error:.2g}"
        )
        nonlin = Decision("nonlinearity", False, "Hertz contacts (nonlinear kernel)", why)
    damped = chain.damped
    stop: float | None = None
    if linear:
        time_d = Decision(
            "time", False, "whole window",
            "the modal solution's free decay after the drive is exact and cheap",
        )  # fmt: skip
    elif not damped:
        time_d = Decision("time", False, "whole window", "no damping: the energy never decays")
    else:
        stop = tol.stop_energy_fraction
        time_d = Decision(
            "time", True, f"stop once energy left <= {stop:.2g} of the input work",
            "after the stop the record is truncated (no sample invented); later velocities are "
            "bounded by sqrt(2 E_left / m0)", stop, "the window after the stop (known after run)",
        )  # fmt: skip
    full_bytes = len(scene.drives) * scene.n_samples * 8 * (2 * chain.n + 1)
    per = {"velocity": scene.n_recorded, "displacement": scene.n_recorded, "drive": 1}
    kept_bytes = len(scene.drives) * scene.n_samples * 8 * sum(per[q] for q in scene.record)
    dropped = [q for q in RECORDABLE if q not in scene.record]
    output = Decision(
        "output", kept_bytes < full_bytes,
        f"{scene.n_recorded} of {chain.n} cylinders, {'+'.join(scene.record)} at "
        f"{scene.sample_rate_Hz / 1e3:g} kS/s",
        "not allocated: " + (", ".join(dropped) if dropped else "nothing")
        + ("" if scene.cylinders is None else f", {chain.n - scene.n_recorded} cylinders"),
        None, f"{kept_bytes / 1e6:.3g} MB of {full_bytes / 1e6:.3g} MB",
    )  # fmt: skip
    return ScenePlan(
        scene=scene,
        chain=run_chain,
        solver="linear-modal" if linear else "nonlinear",
        stop_energy_fraction=stop,
        record=scene.record,
        decisions=(modes, nonlin, time_d, output),
        tolerances=tol,
        overlap_ratio=rho,
    )


def full_plan(scene: Scene) -> ScenePlan:
    """The plan that keeps everything: every mode, the nonlinear kernel, the whole window, every
    quantity (the cylinders asked for): :func:`simulate` as it always ran."""
    chain = scene.chain
    rho = max(overlap_ratio(chain, d) for d in scene.drives)
    full = Decision("all", False, "full model", "reduction not asked for")
    return ScenePlan(scene, chain, "nonlinear", None, RECORDABLE, (full,), overlap_ratio=rho)


def run_scene(plan: ScenePlan) -> SceneResult:
    """Execute ``plan`` (see :func:`plan_scene`). ``meta["fallback"]`` says when the linear
    solution failed its after-run overlap check and the nonlinear kernel was run instead."""
    t0 = time.perf_counter()
    sc = plan.scene
    meta: dict[str, Any] = {"plan": plan.as_dict(), "n_modes": plan.chain.n_modes}
    if plan.solver == "linear-modal":
        lr = linear_response(
            plan.chain, sc.drives, duration_s=sc.duration_s, sample_rate_Hz=sc.sample_rate_Hz,
            cylinders=sc.cylinders, record=plan.record,
        )  # fmt: skip
        rho_real = float(lr.max_overlap_change_m.max()) / plan.chain.delta0_m
        meta["realised_overlap_ratio"] = rho_real
        err = linearisation_error(rho_real, plan.record)
        if err <= plan.tolerances.linear_error:
            meta.update(solver="linear-modal", fallback=False, linear_error_est=err)
            meta["wall_s"] = time.perf_counter() - t0
            return SceneResult(
                lr.time_s, lr.velocity, lr.displacement, lr.drive, lr.cylinders, meta
            )
        meta["fallback"] = (
            f"realised overlap change {rho_real:.2g} delta0 (error {err:.2g}): nonlinear run"
        )
    res = simulate(
        plan.chain, sc.drives, duration_s=sc.duration_s, sample_rate_Hz=sc.sample_rate_Hz,
        cylinders=sc.cylinders, record=plan.record,
        stop_energy_fraction=plan.stop_energy_fraction,
    )  # fmt: skip
    meta["solver"] = "nonlinear"
    meta.setdefault("fallback", False)
    for key in (
        "integrator",
        "dt_s",
        "input_work_J",
        "energy_residual_rel",
        "work_not_in_chain_rel",
        "finite",
    ):
        meta[key] = res.meta[key]
    if plan.stop_energy_fraction is not None:
        n_done = np.asarray(res.meta["samples_computed"])
        left = np.maximum(np.asarray(res.meta["energy_left_rel"]), 0.0)
        left_J = left * np.abs(np.asarray(res.meta["input_work_J"]))
        meta["samples_computed"] = n_done
        meta["stopped_at_s"] = (n_done - 1) / sc.sample_rate_Hz
        meta["stopped_early"] = bool(np.any(n_done < sc.n_samples))
        meta["energy_left_rel"] = left
        meta["velocity_bound_after_stop_m_per_s"] = np.sqrt(
            2.0 * left_J / float(plan.chain.m0_kg.min())
        )
    meta["wall_s"] = time.perf_counter() - t0
    return SceneResult(
        res.time_s,
        res.velocity if "velocity" in plan.record else None,
        res.displacement if "displacement" in plan.record else None,
        res.drive if "drive" in plan.record else None,
        res.cylinders,
        meta,
    )
