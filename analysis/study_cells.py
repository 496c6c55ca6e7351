"""One task of a design study: its cells on the DEM, reduced to the study's metrics.

A task is a fixed set of cells (consecutive cell numbers, :func:`task_cells`). Its cells are
grouped by chain (cells that differ only in the drive share one); each group is one batched
streaming sweep (:func:`sim_backend.dem.sweep.sweep`: one compiled batch per block, the SIMD
lanes filled with the group's drives), recording only the two end cylinders and keeping a few
numbers per trajectory. The kernel's per-lane arithmetic does not depend on the other lanes, so
a cell's numbers do not depend on which cells share its task (``tests/study``); the DEM holds no
randomness, so a cell's result is a function of its parameters alone (no seeds to carry).

Metrics per direction ``d`` (entry cylinder ``e``, far cylinder ``f``, carrier ``f_in``; the
far cylinder's edge ``f_edge`` from the chain's quasi-bands, first local-resonance band):

- ``transmission_d``: ``E_f / E_e`` with ``E = integral v^2 dt`` (dimensionless);
- ``peak_frequency_d``: far-end output peak (Hz) in the band's neighbourhood
  (:func:`analysis.bands.peak_search_range_Hz`), the converted frequency;
- ``detuning_d``: ``(f_out - f_in) / f_in``;
- ``edge_fraction_d``: ``(f_out - f_in) / (f_edge - f_in)``: 0 unconverted, 1 at the edge;
- ``efficiency_d``: far-end energy beyond ``2 sigma_f`` of the carrier on the side of the edge
  (within the peak search range) over ``E_e``;
- ``asymmetry_ratio``: ``transmission_ltr / transmission_rtl``;
- ``error_estimate_d``: the integrator's step-doubling estimate (relative L2, worst of the two
  recorded cylinders), and ``f_edge_d``, ``alpha_actual`` (the chain's asymmetry factor).

A cell whose chain cannot be built, whose run is not finite or whose run raised anything else
(its exception's type and first line kept) is *failed* (NaN metrics, its message kept); one
above the study's ``max_error``, or without an error estimate (NaN: the step 2h unstable; its
message says so), is *inaccurate* (numbers kept, flagged).
"""

from __future__ import annotations

import math
import os
import socket
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from analysis.bands import asymmetry_factor, expected_output_Hz, peak_search_range_Hz
from analysis.spectra import amplitude_spectrum, peak_frequency
from protocols.study import PARAMETERS, CellTable, Study
from protocols.studyfile import STATUS_FAILED, STATUS_INACCURATE, STATUS_OK
from sim_backend.dem import versions

__all__ = [
    "NO_ESTIMATE",
    "STATUS_FAILED",
    "STATUS_INACCURATE",
    "STATUS_OK",
    "StudySetup",
    "TaskResult",
    "cell_chain_spec",
    "check_cells",
    "check_transit",
    "run_task",
    "spectrum_grid_Hz",
    "stored_names",
    "task_cells",
]

#: how the message of a cell without an error estimate starts (status inaccurate: its accuracy
#: cannot be vouched for); before, such a cell was counted "above max_error"
NO_ESTIMATE = "no error estimate"

_CHAIN_PARAMS = tuple(n for n, p in PARAMETERS.items() if p.target == "chain")


@dataclass(frozen=True)
class StudySetup:
    """What every task needs (small, pickled with each task): the study, the base chain as
    JSON (``ChainSpec.model_dump_json``) and the cell table's parameter names."""

    study: Study
    base_chain_json: str
    names: tuple[str, ...]


@dataclass
class TaskResult:
    """The cells of one task: ``cells [k]`` (cell numbers), ``metrics`` name -> [k] float64
    (:func:`stored_names`), ``status [k]`` (:data:`STATUS_OK` ...), ``messages`` (cell ->
    why it failed), ``spectra`` direction -> [k, F] float32 far-end |V| (m) on
    :func:`spectrum_grid_Hz` when the study records them; ``wall_s``, ``worker``;
    ``model_version``: :func:`sim_backend.dem.versions.model_version` where the task ran (a
    cluster's workers may run another installation than the client's)."""

    cells: NDArray[np.int64]
    metrics: dict[str, NDArray[np.float64]]
    status: NDArray[np.int8]
    messages: dict[int, str] = field(default_factory=dict)
    spectra: dict[str, NDArray[np.float32]] = field(default_factory=dict)
    wall_s: float = 0.0
    worker: str = ""
    model_version: str = ""


def stored_names(study: Study) -> list[str]:
    """Every per-cell number a study stores: its metrics, the error estimate and the far edge
    per direction, and the chain's asymmetry factor."""
    names = study.metric_names()
    for d in study.drive.directions:
        names.append(f"f_edge_{d}")
        if study.accuracy.error_estimate:
            names.append(f"error_estimate_{d}")
    names.append("alpha_actual")
    return names


def task_cells(n_cells: int, cells_per_task: int) -> list[NDArray[np.int64]]:
    """The study's tasks: consecutive cell numbers, ``cells_per_task`` each (the last fewer).
    Fixed by the cell numbers and ``cells_per_task`` alone; a continued study runs only the
    cells of each task not done yet (:func:`daq.study_runner.run_study`), so another
    ``cells_per_task`` than the first run's regroups what is left and runs no cell twice."""
    return [
        np.arange(s, min(s + cells_per_task, n_cells), dtype=np.int64)
        for s in range(0, n_cells, cells_per_task)
    ]


def _fmt(name: str, value: float) -> Any:
    info = PARAMETERS[name]
    if info.integer:
        return round(value)
    if info.dimension == "dimensionless":
        return value
    return f"{value!r} {info.unit}"


def _shown(name: str, value: float) -> str:
    """A parameter's value for a message (4 significant digits, its unit with a prefix): a
    Latin hypercube's raw floats read "diameter = 0.015337945819433435 m"."""
    from instruments.units import format_quantity

    info = PARAMETERS[name]
    if info.integer:
        return str(round(value))
    if info.dimension == "dimensionless":
        return f"{value:.4g}"
    if info.dimension == "force":  # newtons as the study file writes them ("0.5 N", not mN)
        return f"{value:.4g} N"
    return format_quantity(value, info.dimension)  # "14.73 mm", "12.35 kHz"


def cell_chain_spec(base_json: str, params: dict[str, float]) -> Any:
    """The chain of a cell: the base chain with the cell's chain parameters (SI floats) applied,
    validated like a chain file (``alpha`` then tilts it, :func:`chain_spec_for_alpha`).
    Raises ``ChainFileError`` (one line naming the field)."""
    return _cell_chain_spec(base_json, tuple(sorted((k, params[k]) for k in params)))


@lru_cache(maxsize=512)
def _cell_chain_spec(base_json: str, items: tuple[tuple[str, float], ...]) -> Any:
    from sim_backend.dem.alpha import chain_spec_for_alpha
    from sim_backend.dem.spec import ChainSpec, chain_spec_from_dict

    params = dict(items)
    base = ChainSpec.model_validate_json(base_json)
    data: dict[str, Any] = base.model_dump(mode="json", exclude_none=True)
    graded = {"n_cylinders", "length_first", "length_last"} & set(params)
    if graded and base.lengths is not None:  # a chain file with explicit lengths: grade it
        lengths = base.lengths_m()
        data.pop("lengths")
        data["n_cylinders"] = len(lengths)
        data["length_first"] = f"{float(lengths[0])!r} m"
        data["length_last"] = f"{float(lengths[-1])!r} m"
    for name, value in params.items():
        if name == "alpha":
            continue
        if name == "bending_mode_ratio":
            data["damping"] = {**data.get("damping", {}), "bending_mode_ratio": value}
        else:
            data[name] = _fmt(name, value)
    spec = chain_spec_from_dict(data, "cell chain")
    if "alpha" in params:
        spec = chain_spec_for_alpha(float(params["alpha"]), spec)
    return spec


def check_cells(setup: StudySetup, table: CellTable) -> tuple[str, str] | None:
    """Build (without simulating) every distinct chain of the study, cheaply (the asymmetry
    factor's tilt is left to the task): ``None``, or ``(parameter, message)`` for the first
    that cannot be built."""
    from sim_backend.dem.spec import ChainFileError

    chain_cols = [i for i, n in enumerate(table.names) if n in _CHAIN_PARAMS and n != "alpha"]
    if not chain_cols:
        return None
    distinct = np.unique(table.values[:, chain_cols], axis=0)
    names = [table.names[i] for i in chain_cols]
    for row in distinct:
        params = dict(zip(names, (float(x) for x in row), strict=True))
        try:
            cell_chain_spec(setup.base_chain_json, params)
        except ChainFileError as exc:
            msg = str(exc).removeprefix("cell chain: ")
            field_name = msg.split(":", 1)[0].split(".")[-1]
            where = next(
                (n for n in names if n == field_name),
                next((n for n in names if n in msg), names[0]),
            )
            values = ", ".join(f"{n} = {_fmt(n, v)}" for n, v in params.items())
            return where, f"no chain for {values}: {msg}"
    return None


def check_transit(setup: StudySetup, table: CellTable) -> tuple[str, str] | None:
    """``None``, or ``("simulation.duration", message)`` naming the cell that needs the longest
    window, where some cell's window cannot hold its burst and the burst's transit to the far
    end: at least ``n - 1`` crossings of ``sqrt(m0 / K)`` (the lightest cylinder's rigid mass
    over the linearised contact stiffness; no wave crosses a contact faster), as
    ``run_protocol`` checks a record. Such a
    cell's far end holds nothing yet, and its metrics would read as a wave that did not pass.
    ``alpha``'s tilt is left out (it moves the lengths a little, not the bound's order)."""
    from instruments.units import format_quantity
    from sim_backend.dem.chain import crossing_time_s, crossing_time_upper_s

    study = setup.study
    window = study.simulation.duration
    chain_cols = [i for i, n in enumerate(table.names) if n in _CHAIN_PARAMS and n != "alpha"]
    # per distinct chain: (transit, cylinders, exact): first a bound from the cylinders' whole
    # masses, without the modes (2000 chains of a Latin hypercube took 13 s to build); the
    # chain itself only where a cell's window fails that bound
    crossing: dict[tuple[float, ...], tuple[float, int, bool]] = {}
    worst: tuple[float, str] | None = None  # the cell that needs the longest window
    for c in range(table.n_cells):
        row = {n: float(table.values[c, j]) for j, n in enumerate(table.names)}
        key = tuple(float(table.values[c, j]) for j in chain_cols)
        params = {table.names[j]: v for j, v in zip(chain_cols, key, strict=True)}
        if key not in crossing:
            spec = cell_chain_spec(setup.base_chain_json, params)
            n = len(spec.lengths_m())
            crossing[key] = (crossing_time_upper_s(spec) * (n - 1), n, False)
        for d in study.drive.directions:
            f_in = row.get(f"carrier_{d}", study.drive.carrier(d))
            burst_s = _burst(study, f_in, row).duration_s
            transit, n, exact = crossing[key]
            if window >= (burst_s + transit) * (1 - 1e-9):
                continue
            if worst is not None and burst_s + transit <= worst[0]:
                continue  # even its bound needs no more than the cell already named
            if not exact:
                with np.errstate(all="ignore"):  # a thick, short chain's highest modes
                    per = crossing_time_s(cell_chain_spec(setup.base_chain_json, params))
                transit = per * (n - 1) if math.isfinite(per) else 0.0
                crossing[key] = (transit, n, True)
            need = burst_s + transit
            if window >= need * (1 - 1e-9) or (worst is not None and need <= worst[0]):
                continue
            values = ", ".join(
                f"{name} = {_shown(name, row[name])}"
                for name in table.names
                if name in _CHAIN_PARAMS or name in ("cycles", f"carrier_{d}")
            )
            at = f" at {values}" if values else ""
            why = (
                f"{format_quantity(window, 'time')} cannot hold the {d} burst "
                f"({format_quantity(burst_s, 'time')}) and its transit to the far end{at} "
                f"(at least {format_quantity(transit, 'time')} over {n - 1} contacts); give at "
                f"least {format_quantity(need, 'time')}"
            )
            worst = need, why
    return None if worst is None else ("simulation.duration", worst[1])


def spectrum_grid_Hz(study: Study) -> NDArray[np.float64]:
    """Frequencies (Hz) of the recorded far-end spectra: the spectrum of a record of the
    study's window, from 0.5 times the lowest carrier to 1.5 times the highest."""
    from analysis.spectra import n_fft_for

    sim = study.simulation
    n = math.floor(sim.duration * sim.rate + 1e-9) + 1
    freq = np.fft.rfftfreq(n_fft_for(n), 1.0 / sim.rate)
    lo, hi = _spectrum_band(study)
    return np.asarray(freq[(freq >= lo) & (freq <= hi)], dtype=np.float64)


def _spectrum_band(study: Study) -> tuple[float, float]:
    carriers = [study.drive.carrier(d) for d in study.drive.directions]
    for d in ("ltr", "rtl"):
        ax = study.parameters.get(f"carrier_{d}")
        if ax is not None and d in study.drive.directions:
            carriers += [v for v in (ax.values or (ax.low, ax.high)) if v is not None]
    return 0.5 * min(carriers), 1.5 * max(carriers)


def _edges(chain: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    from sim_backend import dem

    bands = dem.quasi_bands(chain, min(3, chain.n_modes + 1))
    onset, cutoff = np.asarray(bands.onset_Hz), np.asarray(bands.cutoff_Hz)
    for b in range(onset.shape[1]):
        if np.all(onset[:, b] > 0) and np.all(cutoff[:, b] > onset[:, b]):
            return onset[:, b], cutoff[:, b]
    raise ValueError("the chain has no band with a non-zero onset")


@dataclass(frozen=True)
class _Lane:
    direction: str
    f_in: float
    sigma_f: float
    f_edge: float
    search: tuple[float, float]


class _Reducer:
    """The sweep's reducer: each block's ``[b, 2, S]`` velocities (cylinders #1 and #N) to the
    per-trajectory numbers, the blocks taken in order (the sweep runs them in order)."""

    def __init__(self, lanes: Sequence[_Lane], rate: float, grid: NDArray[np.float64] | None):
        self.lanes = lanes
        self.rate = rate
        self.grid = grid
        self.next = 0

    def __call__(self, v: NDArray[np.float64], time_s: NDArray[np.float64]) -> dict[str, Any]:
        b = v.shape[0]
        lanes = self.lanes[self.next : self.next + b]
        self.next += b
        ltr = np.array([ln.direction == "ltr" for ln in lanes])
        entry = np.where(ltr[:, None], v[:, 0], v[:, 1])
        far = np.where(ltr[:, None], v[:, 1], v[:, 0])
        dt = 1.0 / self.rate
        e_entry = np.sum(entry * entry, axis=-1) * dt
        e_far = np.sum(far * far, axis=-1) * dt
        # energy by frequency (Parseval, no window): |X_k|^2 weights summing to E
        n = far.shape[-1]
        X = np.fft.rfft(far, axis=-1)
        w = np.full(X.shape[-1], 2.0)
        w[0] = 1.0
        if n % 2 == 0:
            w[-1] = 1.0
        e_bins = np.abs(X) ** 2 * w * dt / n
        f_bins = np.fft.rfftfreq(n, dt)
        spec = amplitude_spectrum(far, self.rate)
        peak = np.empty(b)
        conv = np.empty(b)
        for i, ln in enumerate(lanes):
            lo, hi = ln.search
            peak[i] = float(peak_frequency(_row(spec, i), lo, hi, interior=True))
            if ln.f_edge < ln.f_in:
                sel = (f_bins >= lo) & (f_bins < ln.f_in - 2.0 * ln.sigma_f)
            elif ln.f_edge > ln.f_in:
                sel = (f_bins > ln.f_in + 2.0 * ln.sigma_f) & (f_bins <= hi)
            else:
                sel = np.zeros(f_bins.size, dtype=bool)
            conv[i] = float(np.sum(e_bins[i, sel]))
        with np.errstate(divide="ignore", invalid="ignore"):
            out: dict[str, Any] = {
                "transmission": np.where(e_entry > 0, e_far / e_entry, np.nan),
                "efficiency": np.where(e_entry > 0, conv / e_entry, np.nan),
                "peak_frequency": peak,
            }
        if self.grid is not None:
            out["spectrum"] = np.stack(
                [np.interp(self.grid, spec.freq_Hz, spec.magnitude[i]) for i in range(b)]
            ).astype(np.float32)
        return out


def _row(spec: Any, i: int) -> Any:
    from analysis.spectra import Spectrum

    return Spectrum(spec.freq_Hz, spec.magnitude[i])


def _burst(study: Study, f_in: float, params: dict[str, float]) -> Any:
    from instruments.burst import NAMED_BURSTS, Burst

    if "cycles" in params:
        return Burst(f_in, cycles=params["cycles"])
    choice = study.drive.burst
    cycles = choice.cycles if choice.cycles is not None else NAMED_BURSTS[str(choice.shape)]
    return Burst(f_in, cycles=cycles)


def _run_group(
    setup: StudySetup,
    params: dict[str, float],
    rows: list[dict[str, float]],
    grid: NDArray[np.float64] | None,
) -> tuple[dict[str, NDArray[np.float64]], dict[str, NDArray[np.float32]], list[str]]:
    """Cells of one chain (``rows``: each cell's parameters) in one batched sweep: their
    numbers, their spectra, and per cell why it has no error estimate ("" when it has one or
    none was asked for)."""
    from sim_backend import dem
    from sim_backend.dem.sweep import sweep

    study = setup.study
    sim = study.simulation
    spec = cell_chain_spec(setup.base_chain_json, params)
    chain = dem.build_chain(spec)
    onset, cutoff = _edges(chain)
    dirs = study.drive.directions
    kind = study.drive.amplitude_kind()
    drives = []
    lanes = []
    for row in rows:
        for d in dirs:
            f_in = row.get(f"carrier_{d}", study.drive.carrier(d))
            burst = _burst(study, f_in, row)
            drives.append(
                dem.Drive(direction=d, kind=kind, amplitude=row["amplitude"], burst=burst)  # type: ignore[arg-type]
            )
            lanes.append(
                _Lane(d, f_in, burst.sigma_f_Hz, expected_output_Hz(f_in, d, onset, cutoff),
                      peak_search_range_Hz(f_in, onset, cutoff))
            )  # fmt: skip
    reducer = _Reducer(lanes, sim.rate, grid)
    kwargs: dict[str, Any] = {"integrator": sim.integrator}
    if sim.dt is not None:
        kwargs["dt_s"] = sim.dt
    res = sweep(
        chain, drives, duration_s=sim.duration, sample_rate_Hz=sim.rate,
        cylinders=[1, chain.n], keep="metrics", reduce=reducer,
        error_estimate=study.accuracy.error_estimate, **kwargs,
    )  # fmt: skip
    if not res.meta["finite"]:
        raise FloatingPointError("the run diverged (non-finite velocity)")
    k, nd = len(rows), len(dirs)
    m = res.metrics
    out: dict[str, NDArray[np.float64]] = {}
    spectra: dict[str, NDArray[np.float32]] = {}
    for j, d in enumerate(dirs):
        sl = slice(j, k * nd, nd)
        f_ins = np.array([ln.f_in for ln in lanes[sl]])
        f_edge = np.array([ln.f_edge for ln in lanes[sl]])
        f_out = m["peak_frequency"][sl]
        out[f"transmission_{d}"] = m["transmission"][sl]
        out[f"peak_frequency_{d}"] = f_out
        out[f"detuning_{d}"] = (f_out - f_ins) / f_ins
        with np.errstate(divide="ignore", invalid="ignore"):
            out[f"edge_fraction_{d}"] = np.where(
                f_edge != f_ins, (f_out - f_ins) / (f_edge - f_ins), np.nan
            )
        out[f"efficiency_{d}"] = m["efficiency"][sl]
        out[f"f_edge_{d}"] = f_edge
        if "error_estimate_rel" in m:
            out[f"error_estimate_{d}"] = m["error_estimate_rel"][sl]
        if grid is not None:
            spectra[d] = m["spectrum"][sl]
    if "transmission_ltr" in out and "transmission_rtl" in out:
        with np.errstate(divide="ignore", invalid="ignore"):
            out["asymmetry_ratio"] = out["transmission_ltr"] / out["transmission_rtl"]
    out["alpha_actual"] = np.full(k, asymmetry_factor(onset, cutoff))
    return out, spectra, _missing_estimates(res, lanes, k, nd)


def _missing_estimates(res: Any, lanes: Sequence[_Lane], k: int, nd: int) -> list[str]:
    """Per cell (``k`` of them, ``nd`` directions each), why its error estimate is missing:
    ``"no error estimate (ltr: the step 2h is unstable)"``, or "" for a cell that has one."""
    est = res.metrics.get("error_estimate_rel")
    if est is None:
        return [""] * k
    methods = list(res.meta.get("error_estimate_method", [])) or [""] * len(lanes)
    out = []
    for i in range(k):
        whys: dict[str, list[str]] = {}  # why -> the directions it is said of
        for j in range(nd):
            r = i * nd + j
            if not math.isfinite(float(est[r])):
                method = methods[r] if r < len(methods) else ""
                why = method.removeprefix("none: ") if method.startswith("none") else ""
                whys.setdefault(why or "not finite", []).append(lanes[r].direction)
        said = "; ".join(f"{', '.join(ds)}: {why}" for why, ds in whys.items())
        out.append(f"{NO_ESTIMATE} ({said})" if whys else "")
    return out


def run_task(
    setup: StudySetup, cells: NDArray[np.int64], values: NDArray[np.float64]
) -> TaskResult:
    """Run the cells ``cells [k]`` whose parameters are ``values [k, P]`` (SI, in the order of
    ``setup.names``): one batched sweep per distinct chain. Never raises for a cell's own
    failure (it is reported in the result)."""
    t0 = time.perf_counter()
    study = setup.study
    names = stored_names(study)
    k = len(cells)
    metrics = {n: np.full(k, np.nan) for n in names}
    status = np.full(k, STATUS_OK, dtype=np.int8)
    messages: dict[int, str] = {}
    grid = spectrum_grid_Hz(study) if study.record_spectra else None
    spectra: dict[str, NDArray[np.float32]] = {}
    if grid is not None:
        spectra = {d: np.full((k, grid.size), np.nan, np.float32) for d in study.drive.directions}
    chain_cols = [i for i, n in enumerate(setup.names) if n in _CHAIN_PARAMS]
    groups: dict[tuple[float, ...], list[int]] = {}
    for i in range(k):
        groups.setdefault(tuple(float(values[i, c]) for c in chain_cols), []).append(i)
    for key, members in groups.items():
        params = {setup.names[c]: v for c, v in zip(chain_cols, key, strict=True)}
        rows = [{n: float(values[i, j]) for j, n in enumerate(setup.names)} for i in members]
        try:
            out, spec_out, missing = _run_group(setup, params, rows, grid)
        except Exception as exc:  # a cell's failure, whatever raised it
            # the model's own refusals (ValueError, ArithmeticError) say what they are; any
            # other (a bug, a numba error) is named by its type. Before, one stopped the whole
            # study, and every rerun stopped at the same cell. Ctrl-C and the stop signals
            # (KeyboardInterrupt) still end the study.
            first = str(exc).splitlines()[0] if str(exc) else ""
            expected = isinstance(exc, ValueError | ArithmeticError)
            why = first if expected and first else f"{type(exc).__name__}: {first}".rstrip(": ")
            for i in members:
                status[i] = STATUS_FAILED
                messages[int(cells[i])] = why
            continue
        for i, why in zip(members, missing, strict=True):
            if why:
                messages[int(cells[i])] = why
        idx = np.asarray(members)
        for n, arr in out.items():
            if n in metrics:
                metrics[n][idx] = arr
        for d, sp in spec_out.items():
            spectra[d][idx] = sp
    if study.accuracy.error_estimate:
        err = np.stack([metrics[f"error_estimate_{d}"] for d in study.drive.directions])
        worst = np.max(err, axis=0)
        # above max_error, or no estimate (NaN: its message says why): not within the accuracy
        # asked for either way, flagged alike; the study's last line counts them apart
        bad = (status == STATUS_OK) & ~(worst <= study.accuracy.max_error)
        status[bad] = STATUS_INACCURATE
    return TaskResult(
        cells=np.asarray(cells, dtype=np.int64),
        metrics=metrics,
        status=status,
        messages=messages,
        spectra=spectra,
        wall_s=time.perf_counter() - t0,
        worker=f"{socket.gethostname()}:{os.getpid()}",
        model_version=versions.model_version(),
    )
