"""Fit the chain model's uncertain parameters to a measured scan (``biafc calibrate``).

Method
------
1. **Which points.** The low-amplitude points of the scan, where the chain is linear: every
   amplitude whose linearised response (nominal chain, the bench's stroke) changes no
   contact's overlap by more than ``LINEAR_LIMIT`` of the static overlap ``delta0``, and of
   those the points that were measured, not failed and not clipped. At least ``MIN_CYLINDERS``
   distinct cylinders are needed; otherwise :class:`CalibrationError` says what the fit needs.
2. **Which model.** The linear-response solver (exact for the linearised chain, one solution
   per direction at unit drive, scaled by each amplitude): about 0.1 s per evaluation on the
   default chain, so the fit needs no DEM.
3. **Which residual.** Magnitude spectra of every linear point (``FIT_BAND_HZ``, every
   ``PAD_FACTOR``-th bin of the zero-padded FFT so neighbouring residuals are nearly
   independent), model minus measurement, each (direction, amplitude) divided by its measured
   maximum. Magnitudes are blind to the trigger's timing (a jitter of the trigger shifts the
   record, not its spectrum magnitude); where the band edges sit (the preload and the
   diameter: contact stiffness and resonators), how fast the response dies along the chain
   (damping) and its level (the stroke) all show in them.
4. **How.** ``scipy.optimize.least_squares`` (trust-region reflective, bounds) on the
   logarithms of the parameters relative to their start values, from the values the run file
   records (its ``/chain``, the default damping, the bench's stroke), in two stages: first on
   spectra smoothed by a Gaussian of ``SMOOTH_HZ`` (narrow resonances that do not yet overlap
   make a cost with many local minima; smoothed, it is that of the band edges and levels),
   then on the spectra as they are, from the first stage's values.
5. **Uncertainty.** From the Jacobian at the solution, ``cov = s^2 (J^T J)^-1`` with ``s^2``
   the residual variance; standard deviations by the delta method and the correlation matrix.
   They assume the model is right and the residuals independent: they are the spread a repeat
   of the measurement would give, not the model's own error.

Parameters (``--fit``): ``F0`` (preload, N), ``diameter`` (m), ``damping`` (the resonators'
modal damping ratio; the contact dashpots stay as the chain sets them), ``stroke`` (the piezo's
m/V; a scale of every drive), ``E`` (Young's modulus, Pa).

Progress: ``calibrate(..., progress=say)`` says what is fitted to how many points and
residuals, each stage as it starts, and about once a second within a stage the evaluations so
far and the current relative residual (a fit takes 8 s on a ``linear_lowamp`` run, 10 s with
the DEM stage, and had said nothing until its table).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d
from scipy.optimize import least_squares

from analysis.compare import point_states
from analysis.fit_jacobian import LastValue, forward_jacobian
from analysis.model_run import (
    RunSetup,
    _on_time_axis,
    chain_spec_of_run,
    model_duration_s,
    resonator_damping,
    run_setup,
    with_resonator_damping,
)
from analysis.spectra import PAD_FACTOR, amplitude_spectrum
from protocols.runfile import RunData
from sim_backend.dem import ChainSpec, Drive, build_chain
from sim_backend.dem.linear_response import linear_response

__all__ = [
    "FIT_BAND_HZ",
    "LINEAR_LIMIT",
    "MIN_CYLINDERS",
    "PARAMETERS",
    "CalibrationError",
    "CalibrationResult",
    "LinearData",
    "calibrate",
    "linear_data",
    "parse_fit",
]

#: an amplitude is linear when no contact's overlap changes by more than this fraction of delta0
LINEAR_LIMIT = 0.1
#: fewest distinct cylinders with linear points the fit accepts
MIN_CYLINDERS = 5
#: the first stage of the fit compares spectra smoothed by a Gaussian of this width (Hz)
SMOOTH_HZ = 150.0
#: band (Hz) of the spectral residual: the first local-resonance bands and their neighbours
FIT_BAND_HZ = (3.0e3, 14.0e3)

#: name -> (unit shown, scale shown, lower and upper bound relative to the start)
PARAMETERS: dict[str, tuple[str, float, float, float]] = {
    "F0": ("N", 1.0, 0.2, 5.0),
    "diameter": ("mm", 1e3, 0.8, 1.25),
    "damping": ("", 1.0, 0.02, 50.0),
    "stroke": ("um/V", 1e6, 0.2, 5.0),
    "E": ("GPa", 1e-9, 0.7, 1.4),
}
SI_UNITS = {"F0": "N", "diameter": "m", "damping": "1", "stroke": "m/V", "E": "Pa"}
ALIASES = {"f0": "F0", "preload": "F0", "d": "diameter", "youngs_modulus": "E", "e": "E"}


class CalibrationError(ValueError):
    """The run cannot be calibrated; the message says what the fit needs."""


def parse_fit(text: str | Sequence[str]) -> tuple[str, ...]:
    """``"F0,damping,diameter,stroke"`` -> the parameter names (refuses unknown ones)."""
    items = text.split(",") if isinstance(text, str) else list(text)
    out: list[str] = []
    for raw in items:
        name = raw.strip()
        if not name:
            continue
        name = ALIASES.get(name.lower(), ALIASES.get(name, name))
        if name not in PARAMETERS:
            raise CalibrationError(
                f"--fit: unknown parameter {raw.strip()!r} (choose from {', '.join(PARAMETERS)})"
            )
        if name not in out:
            out.append(name)
    if not out:
        raise CalibrationError(f"--fit: name at least one of {', '.join(PARAMETERS)}")
    return tuple(out)


def _with(spec: ChainSpec, values: dict[str, float]) -> ChainSpec:
    """``spec`` with the chain parameters of ``values`` replaced (``stroke`` is not a chain's)."""
    upd: dict[str, Any] = {}
    if "F0" in values:
        upd["preload"] = values["F0"]
    if "diameter" in values:
        upd["diameter"] = values["diameter"]
    if "damping" in values:
        spec = with_resonator_damping(spec, values["damping"])
    if "E" in values:
        upd["material"] = spec.material.model_copy(update={"youngs_modulus": values["E"]})
    return spec.model_copy(update=upd)


def _start_values(spec: ChainSpec, setup: RunSetup) -> dict[str, float]:
    return {
        "F0": float(spec.preload),
        "diameter": float(spec.diameter),
        "damping": resonator_damping(spec),
        "stroke": float(setup.stroke_m_per_V) if setup.stroke_m_per_V is not None else 1.0,
        "E": float(spec.material.youngs_modulus),
    }


@dataclass(frozen=True)
class LinearData:
    """The linear points of a run, ready for the fit.

    per direction: ``amplitudes`` (indices), ``mask [A_lin, C]`` (points used), ``measured``
    ``[A_lin, C, F]`` magnitude spectra (m), ``scale [A_lin]`` (their maxima); ``freq_Hz [F]``.
    ``refused`` lists what was left out and why (for the report).
    """

    setup: RunSetup
    amplitudes: dict[str, list[int]]
    mask: dict[str, NDArray[np.bool_]]
    measured: dict[str, NDArray[np.float64]]
    scale: dict[str, NDArray[np.float64]]
    freq_sel: NDArray[np.bool_]
    notes: list[str] = field(default_factory=list)

    @property
    def n_points(self) -> int:
        return int(sum(int(m.sum()) for m in self.mask.values()))

    def cylinders(self) -> set[int]:
        out: set[int] = set()
        for d, m in self.mask.items():
            cyl = self.setup.directions[d].cylinders
            out.update(int(c) for c in cyl[np.any(m, axis=0)])
        return out


def _bin_width_Hz(data: LinearData) -> float:
    ds = next(iter(data.setup.directions.values()))
    f = amplitude_spectrum(np.zeros(ds.time_s.size), ds.sample_rate_Hz).freq_Hz[data.freq_sel]
    return float(f[1] - f[0]) if f.size > 1 else 1.0


def _spectra(v: NDArray[np.float64], rate: float, sel: NDArray[np.bool_]) -> NDArray[np.float64]:
    return amplitude_spectrum(v, rate).magnitude[..., sel]


def _freq_sel(n_samples: int, rate: float) -> NDArray[np.bool_]:
    spec = amplitude_spectrum(np.zeros(n_samples), rate)
    f = spec.freq_Hz
    sel = (f >= FIT_BAND_HZ[0]) & (f <= FIT_BAND_HZ[1])
    keep = np.zeros_like(sel)
    idx = np.flatnonzero(sel)[::PAD_FACTOR]
    keep[idx] = True
    return keep


def linear_data(run: RunData, spec: ChainSpec, setup: RunSetup | None = None) -> LinearData:
    """Select the linear points of ``run`` (see the module docstring) or raise
    :class:`CalibrationError` saying what the fit needs."""
    setup = setup if setup is not None else run_setup(run)
    chain = build_chain(spec)
    delta0 = float(chain.delta0_m)
    amps: dict[str, list[int]] = {}
    masks: dict[str, NDArray[np.bool_]] = {}
    meas: dict[str, NDArray[np.float64]] = {}
    scales: dict[str, NDArray[np.float64]] = {}
    notes: list[str] = []
    sel: NDArray[np.bool_] | None = None
    n_clipped = n_nonlinear = 0
    ratios: list[float] = []
    for d, ds in setup.directions.items():
        scan = run.scans[d]
        unit = Drive(ds.direction, ds.kind, 1.0, ds.burst)
        lr = linear_response(
            chain,
            [unit],
            duration_s=model_duration_s(float(ds.time_s[-1]), ds.sample_rate_Hz),
            sample_rate_Hz=ds.sample_rate_Hz,
            cylinders=[1],
            record=(),
        )
        ratio = ds.drive_SI * float(lr.max_overlap_change_m[0]) / delta0
        ratios += [float(r) for r in ratio]
        vel = np.asarray(scan.velocity, dtype=np.float64)
        state = point_states(scan.done, vel, setup.clip_m_per_s)
        lin = [a for a in range(len(ds.drive_SI)) if ratio[a] <= LINEAR_LIMIT]
        n_nonlinear += int(np.count_nonzero(state[ratio > LINEAR_LIMIT] == "ok"))
        n_clipped += int(np.count_nonzero(state == "clipped"))
        if not lin:
            continue
        ok = state[lin] == "ok"
        if not np.any(ok):
            continue
        if sel is None:
            sel = _freq_sel(vel.shape[-1], ds.sample_rate_Hz)
        m = _spectra(np.where(ok[..., None], vel[lin], 0.0), ds.sample_rate_Hz, sel)
        m[~ok] = 0.0
        amps[d], masks[d], meas[d] = lin, ok, m
        scales[d] = np.maximum(m.max(axis=(1, 2)), 1e-300)
    data = LinearData(
        setup, amps, masks, meas, scales, sel if sel is not None else np.zeros(0, bool), notes
    )
    n_cyl = len(data.cylinders())
    if data.n_points == 0:
        worst = f"{min(ratios):.2g}" if ratios else "n/a"
        raise CalibrationError(
            f"{run.path}: no linear point to fit: calibrate needs measured, unclipped points at "
            f"low amplitude, where no contact's overlap changes by more than "
            f"{LINEAR_LIMIT:.0%} of delta0 = {delta0 * 1e6:.3g} um (here the smallest amplitude "
            f"reaches {worst} delta0; {n_clipped} points clipped, {n_nonlinear} unclipped "
            f"points nonlinear): add amplitudes of a few tens of nm"
        )
    if n_cyl < MIN_CYLINDERS:
        raise CalibrationError(
            f"{run.path}: linear points on {n_cyl} cylinder(s); calibrate needs them on at "
            f"least {MIN_CYLINDERS} cylinders along the chain (the band edges and the "
            "attenuation along it pin the parameters): scan more cylinders"
        )
    if n_nonlinear:
        notes.append(f"{n_nonlinear} nonlinear points left out of the linear fit")
    if n_clipped:
        notes.append(f"{n_clipped} clipped points left out of the fit")
    return data


@dataclass
class CalibrationResult:
    """A fit: the parameters (``names``), start and fitted values (SI), standard deviations,
    correlation matrix, relative residual RMS before and after, the fitted chain and stroke."""

    names: tuple[str, ...]
    start: dict[str, float]
    values: dict[str, float]
    std: dict[str, float]
    correlation: NDArray[np.float64]
    residual_before: float
    residual_after: float
    n_points: int
    n_residuals: int
    n_evaluations: int
    wall_s: float
    spec: ChainSpec
    stroke_m_per_V: float | None
    success: bool
    message: str
    notes: list[str] = field(default_factory=list)
    #: the DEM stage (``--nonlinear``): residual before and after, points, evaluations
    dem_stage: dict[str, float] = field(default_factory=dict)

    def table(self) -> str:
        """The fitted values with their uncertainty, the correlations and the residuals."""
        lines = [f"{'parameter':>10}  {'start':>10}  {'fitted':>10}  {'+/- (1 sigma)':>13}  unit"]
        for n in self.names:
            unit, k, _, _ = PARAMETERS[n]
            lines.append(
                f"{n:>10}  {self.start[n] * k:10.5g}  {self.values[n] * k:10.5g}  "
                f"{self.std[n] * k:13.2g}  {unit}"
            )
        if len(self.names) > 1:
            lines.append("correlations:")
            head = "".join(f"{n:>10}" for n in self.names)
            lines.append(f"{'':>10}{head}")
            for i, n in enumerate(self.names):
                row = "".join(f"{self.correlation[i, j]:10.2f}" for j in range(len(self.names)))
                lines.append(f"{n:>10}{row}")
        lines.append(
            f"relative spectral residual (RMS, {self.n_points} linear points, "
            f"{self.n_residuals} residuals): {self.residual_before:.4f} before, "
            f"{self.residual_after:.4f} after ({self.n_evaluations} model evaluations, "
            f"{self.wall_s:.1f} s)"
        )
        lines.append(
            "the +/- are statistical: the spread a repeat would give were the model exact; the "
            "model's own error is not in them (judge the fit by its residual against the noise "
            "floor: biafc compare)"
        )
        if self.dem_stage:
            st = self.dem_stage
            lines.append(
                f"DEM stage on every unclipped point ({int(st['points'])} points, linear and "
                f"nonlinear): relative spectral residual {st['before']:.4f} from the linear "
                f"fit, {st['after']:.4f} after ({int(st['evaluations'])} DEM batches)"
            )
        lines += self.notes
        if not self.success:
            lines.append(f"the fit did not converge: {self.message}")
        return "\n".join(lines)

    def chain_yaml(self, source: str = "") -> str:
        """The fitted chain as a chain file, with the fit in its header comments."""
        head = [f"# chain fitted by biafc calibrate{(' to ' + source) if source else ''}"]
        for n in self.names:
            unit, k, _, _ = PARAMETERS[n]
            head.append(
                f"# {n}: {self.values[n] * k:.6g} +/- {self.std[n] * k:.2g} {unit} "
                f"(start {self.start[n] * k:.6g})"
            )
        if self.stroke_m_per_V is not None and "stroke" in self.names:
            head.append(
                f"# piezo stroke is the bench's, not the chain's: biafc compare RUN.h5 --chain "
                f"THIS.yaml --piezo-stroke '{self.stroke_m_per_V * 1e6:.6g} um/V'"
            )
        head.append(
            f"# residual {self.residual_before:.4f} -> {self.residual_after:.4f} "
            f"({self.n_points} linear points)"
        )
        return "\n".join(head) + "\n" + self.spec.to_yaml()

    def as_dict(self) -> dict[str, Any]:
        return {
            "parameters": {
                n: {
                    "start": self.start[n],
                    "value": self.values[n],
                    "std": self.std[n],
                    "unit_SI": SI_UNITS[n],
                }
                for n in self.names
            },
            "correlation": self.correlation.tolist(),
            "residual_before": self.residual_before,
            "residual_after": self.residual_after,
            "points": self.n_points,
            "residuals": self.n_residuals,
            "evaluations": self.n_evaluations,
            "wall_s": self.wall_s,
            "success": self.success,
            "message": self.message,
            "dem_stage": dict(self.dem_stage),
        }


class _Model:
    """Residuals of a parameter vector (logs of the values over the start values)."""

    def __init__(
        self,
        data: LinearData,
        spec: ChainSpec,
        start: dict[str, float],
        names: tuple[str, ...],
    ) -> None:
        self.data, self.spec, self.start, self.names = data, spec, start, names
        self.n_eval = 0
        self.smooth_bins = 0.0
        self._measured = dict(data.measured)

    def set_smoothing(self, bins: float) -> None:
        """Compare spectra smoothed by a Gaussian of ``bins`` frequency bins (0: as they are)."""
        self.smooth_bins = bins
        self._measured = {d: self._smooth(m) for d, m in self.data.measured.items()}

    def _smooth(self, m: NDArray[np.float64]) -> NDArray[np.float64]:
        if self.smooth_bins <= 0:
            return m
        return np.asarray(gaussian_filter1d(m, self.smooth_bins, axis=-1, mode="nearest"))

    def values(self, x: NDArray[np.float64]) -> dict[str, float]:
        v = dict(self.start)
        for n, xi in zip(self.names, x, strict=True):
            v[n] = self.start[n] * math.exp(float(xi))
        return v

    def unit_spectra(self, v: dict[str, float]) -> dict[str, NDArray[np.float64]]:
        """Per direction ``[C, F]``: the model's spectra per metre (or N) of drive."""
        chain = build_chain(_with(self.spec, v))
        out: dict[str, NDArray[np.float64]] = {}
        for d in self.data.amplitudes:
            ds = self.data.setup.directions[d]
            lr = linear_response(
                chain,
                [Drive(ds.direction, ds.kind, 1.0, ds.burst)],
                duration_s=model_duration_s(float(ds.time_s[-1]), ds.sample_rate_Hz),
                sample_rate_Hz=ds.sample_rate_Hz,
                cylinders=[int(c) for c in ds.cylinders],
                record=("velocity",),
            )
            assert lr.velocity is not None
            v_t = _on_time_axis(lr.time_s, lr.velocity[0], ds.time_s)
            out[d] = _spectra(v_t, ds.sample_rate_Hz, self.data.freq_sel)
        return out

    def residuals(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        self.n_eval += 1
        v = self.values(x)
        stroke_f = v["stroke"] / self.start["stroke"]
        unit = self.unit_spectra(v)
        parts: list[NDArray[np.float64]] = []
        for d, lin in self.data.amplitudes.items():
            drive = self.data.setup.directions[d].drive_SI[lin] * stroke_f
            pred = drive[:, None, None] * self._smooth(unit[d])[None]
            r = (pred - self._measured[d]) / self.data.scale[d][:, None, None]
            parts.append(r[self.data.mask[d]].ravel())
        return np.concatenate(parts)


def calibrate(
    run: RunData,
    fit: Sequence[str] = ("F0", "damping", "diameter", "stroke"),
    *,
    chain_spec: ChainSpec | None = None,
    max_evaluations: int = 200,
    nonlinear: bool = False,
    max_dem_evaluations: int = 40,
    progress: Callable[[str], None] | None = None,
    progress_every_s: float = 1.0,
) -> CalibrationResult:
    """Fit ``fit`` to the linear points of ``run`` (see the module docstring); with
    ``nonlinear``, then refine on every unclipped point (linear and nonlinear) with the batched
    DEM, from the linear fit (values, uncertainties and correlations are then this stage's).

    ``progress(line)``, when given, gets a start line (the parameters, points and residuals),
    a line as each stage starts and, every ``progress_every_s`` within a stage, the evaluations
    so far and the current relative residual."""

    def say(line: str) -> None:
        if progress is not None:
            progress(line)

    t0 = time.perf_counter()
    names = parse_fit(list(fit))
    spec = chain_spec if chain_spec is not None else chain_spec_of_run(run)
    setup = run_setup(run)
    if "stroke" in names and setup.stroke_m_per_V is None:
        raise CalibrationError(
            f"{run.path}: the file records no bench (no amplifier gain or piezo stroke): "
            "leave stroke out of --fit"
        )
    data = linear_data(run, spec, setup)
    start = _start_values(spec, setup)
    model = _Model(data, spec, start, names)
    lo = np.array([math.log(PARAMETERS[n][2]) for n in names])
    hi = np.array([math.log(PARAMETERS[n][3]) for n in names])
    x0 = np.zeros(len(names))
    r0 = model.residuals(x0)
    norm = math.sqrt(
        sum(
            float(np.sum((data.measured[d] / data.scale[d][:, None, None])[data.mask[d]] ** 2))
            for d in data.amplitudes
        )
    )
    n_stages = 3 if nonlinear else 2
    say(
        f"fitting {', '.join(names)} to {data.n_points} linear points ({r0.size} residuals), "
        f"relative residual {float(np.linalg.norm(r0)) / norm:.4f} at the start values; "
        f"{n_stages} stages"
    )
    # stage 1 on smoothed spectra: narrow resonances that do not yet overlap give a cost
    # with many local minima; smoothed, the landscape is that of the band edges and levels
    bin_Hz = _bin_width_Hz(data)
    model.set_smoothing(SMOOTH_HZ / bin_Hz)
    say(f"stage 1 of {n_stages}: linear-response model, spectra smoothed by {SMOOTH_HZ:g} Hz")
    # absolute steps in x = log(value / start) (analysis.fit_jacobian): relative ones vanish
    # where the start values are right; a fresh memo for each stage's residuals
    f1 = LastValue(_Watched(model.residuals, norm, "stage 1", say, progress_every_s))
    coarse = least_squares(
        f1, x0, jac=forward_jacobian(f1, 1e-4, hi), bounds=(lo, hi), method="trf",
        max_nfev=max_evaluations, xtol=1e-6, ftol=1e-6,
    )  # fmt: skip
    model.set_smoothing(0.0)
    say(f"stage 2 of {n_stages}: linear-response model, spectra as they are")
    f2 = LastValue(_Watched(model.residuals, norm, "stage 2", say, progress_every_s))
    sol = least_squares(
        f2, coarse.x, jac=forward_jacobian(f2, 1e-4, hi), bounds=(lo, hi), method="trf",
        max_nfev=max_evaluations, xtol=1e-10, ftol=1e-10,
    )  # fmt: skip
    values = model.values(sol.x)
    m = int(sol.jac.shape[0])
    std, corr = _uncertainty(sol, values, names)
    notes = list(data.notes)
    residual_before = float(np.linalg.norm(r0)) / norm
    residual_after = float(np.linalg.norm(sol.fun)) / norm
    n_eval = model.n_eval
    dem: dict[str, float] = {}
    if nonlinear:
        dm = _DemModel(run, setup, spec, start, names)
        if dm.n_points == 0:
            notes.append("--nonlinear: no unclipped point to fit with the DEM")
        else:
            say(
                f"stage 3 of 3: the DEM on {dm.n_points} unclipped points (linear and "
                f"nonlinear), at most {max_dem_evaluations} DEM batches"
            )
            x1 = np.asarray(sol.x, dtype=np.float64)
            d0 = float(np.linalg.norm(dm.residuals(x1))) / dm.norm
            f3 = LastValue(_Watched(dm.residuals, dm.norm, "stage 3", say, progress_every_s))
            sol = least_squares(
                f3, x1, jac=forward_jacobian(f3, 1e-3, hi), bounds=(lo, hi), method="trf",
                max_nfev=max_dem_evaluations, xtol=1e-8, ftol=1e-8,
            )  # fmt: skip
            values = dm.values(sol.x)
            std, corr = _uncertainty(sol, values, names)
            dem = {
                "before": d0,
                "after": float(np.linalg.norm(sol.fun)) / dm.norm,
                "points": float(dm.n_points),
                "evaluations": float(dm.n_eval),
            }
            n_eval += dm.n_eval
    at_bound = [n for i, n in enumerate(names) if sol.active_mask[i] != 0]
    if at_bound:
        notes.append(f"at a bound of the search range: {', '.join(at_bound)}")
    fitted_spec = _with(spec, {n: values[n] for n in names if n != "stroke"})
    return CalibrationResult(
        names=names,
        start={n: start[n] for n in names},
        values={n: values[n] for n in names},
        std=std,
        correlation=corr,
        residual_before=residual_before,
        residual_after=residual_after,
        n_points=data.n_points,
        n_residuals=m,
        n_evaluations=n_eval,
        wall_s=time.perf_counter() - t0,
        spec=fitted_spec,
        stroke_m_per_V=values["stroke"] if setup.stroke_m_per_V is not None else None,
        success=bool(sol.success),
        message=str(sol.message),
        notes=notes,
        dem_stage=dem,
    )


class _Watched:
    """A residual function that says, at most every ``every_s``, how many times it was
    evaluated and the relative residual of its last evaluation (its norm over ``norm``)."""

    def __init__(
        self,
        fn: Callable[[NDArray[np.float64]], NDArray[np.float64]],
        norm: float,
        label: str,
        say: Callable[[str], None],
        every_s: float,
    ) -> None:
        self.fn, self.norm, self.label, self.say, self.every_s = fn, norm, label, say, every_s
        self.n = 0
        self._last = time.perf_counter()

    def __call__(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        r = self.fn(x)
        self.n += 1
        now = time.perf_counter()
        if now - self._last >= self.every_s:
            self._last = now
            rel = float(np.linalg.norm(r)) / self.norm if self.norm > 0 else math.nan
            self.say(f"  {self.label}: {self.n} evaluations, relative residual {rel:.4f}")
        return r


def _uncertainty(
    sol: Any, values: dict[str, float], names: tuple[str, ...]
) -> tuple[dict[str, float], NDArray[np.float64]]:
    """Standard deviations (delta method) and correlations from the Jacobian at the solution."""
    J = sol.jac
    m, p = J.shape
    s2 = 2.0 * float(sol.cost) / max(1, m - p)
    try:
        cov = np.linalg.inv(J.T @ J) * s2
    except np.linalg.LinAlgError:
        cov = np.full((p, p), np.nan)
    sd_x = np.sqrt(np.abs(np.diag(cov)))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd_x, sd_x)
    return {n: values[n] * float(sd_x[i]) for i, n in enumerate(names)}, corr


class _DemModel:
    """Residuals of every unclipped, measured point (linear and nonlinear) against the batched
    DEM (:func:`analysis.model_run.predict`): the second, optional stage."""

    def __init__(
        self,
        run: RunData,
        setup: RunSetup,
        spec: ChainSpec,
        start: dict[str, float],
        names: tuple[str, ...],
    ) -> None:
        self.setup, self.spec, self.start, self.names = setup, spec, start, names
        self.n_eval = 0
        self.mask: dict[str, NDArray[np.bool_]] = {}
        self.measured: dict[str, NDArray[np.float64]] = {}
        self.scale: dict[str, NDArray[np.float64]] = {}
        self.sel = np.zeros(0, dtype=bool)
        for d, ds in setup.directions.items():
            scan = run.scans[d]
            vel = np.asarray(scan.velocity, dtype=np.float64)
            ok = point_states(scan.done, vel, setup.clip_m_per_s) == "ok"
            if not np.any(ok):
                continue
            if self.sel.size == 0:
                self.sel = _freq_sel(vel.shape[-1], ds.sample_rate_Hz)
            m = _spectra(np.where(ok[..., None], vel, 0.0), ds.sample_rate_Hz, self.sel)
            m[~ok] = 0.0
            self.mask[d], self.measured[d] = ok, m
            self.scale[d] = np.maximum(m.max(axis=(1, 2)), 1e-300)
        self.n_points = int(sum(int(k.sum()) for k in self.mask.values()))
        self.norm = math.sqrt(
            sum(
                float(np.sum((self.measured[d] / self.scale[d][:, None, None])[self.mask[d]] ** 2))
                for d in self.mask
            )
        )

    def values(self, x: NDArray[np.float64]) -> dict[str, float]:
        v = dict(self.start)
        for n, xi in zip(self.names, x, strict=True):
            v[n] = self.start[n] * math.exp(float(xi))
        return v

    def residuals(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        from analysis.model_run import predict

        self.n_eval += 1
        v = self.values(x)
        setup = self.setup
        if setup.stroke_m_per_V is not None:
            setup = setup.with_stroke(v["stroke"])
        pred = predict(setup, build_chain(_with(self.spec, v)), directions=tuple(self.mask))
        parts: list[NDArray[np.float64]] = []
        for d, ok in self.mask.items():
            ds = setup.directions[d]
            p = _spectra(pred[d], ds.sample_rate_Hz, self.sel)
            r = (p - self.measured[d]) / self.scale[d][:, None, None]
            parts.append(r[ok].ravel())
        return np.concatenate(parts)


def fit_spectra(
    run: RunData, result: CalibrationResult, chain_spec: ChainSpec | None = None
) -> dict[str, dict[str, NDArray[np.float64]]]:
    """For the before/after figure: per direction, ``measured``, ``start`` and ``fitted``
    magnitude spectra ``[A_lin, C, F]`` of the linear points (0 where a point is left out),
    ``freq_Hz [F]`` and ``cylinders [C]``."""
    spec = chain_spec if chain_spec is not None else chain_spec_of_run(run)
    setup = run_setup(run)
    data = linear_data(run, spec, setup)
    start = _start_values(spec, setup)
    model = _Model(data, spec, start, result.names)
    fitted = dict(start)
    fitted.update(result.values)
    s_unit, f_unit = model.unit_spectra(start), model.unit_spectra(fitted)
    stroke_f = fitted["stroke"] / start["stroke"]
    freq = amplitude_spectrum(
        np.zeros(next(iter(run.scans.values())).time_s.size),
        next(iter(setup.directions.values())).sample_rate_Hz,
    ).freq_Hz[data.freq_sel]
    out: dict[str, dict[str, NDArray[np.float64]]] = {}
    for d, lin in data.amplitudes.items():
        drive = setup.directions[d].drive_SI[lin]
        out[d] = {
            "measured": data.measured[d],
            "start": drive[:, None, None] * s_unit[d][None],
            "fitted": drive[:, None, None] * stroke_f * f_unit[d][None],
            "freq_Hz": freq,
            "cylinders": setup.directions[d].cylinders.astype(np.float64),
            "mask": data.mask[d].astype(np.float64),
        }
    return out
