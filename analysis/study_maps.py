"""What a design study shows: phase diagrams, the asymmetry sweep and the best designs.

- :func:`phase_map`: one metric over two chosen parameters (the heat map of a design map);
  every other parameter either fixed (``fixed={"amplitude": 2e-6}``: the cells at the nearest
  value the study holds) or marginalised (``reduce``: mean, median, max or min over them).
  Parameters with many distinct values (a Latin hypercube) are binned (``bins`` per axis).
- :func:`alpha_sweep_from_study`: the paper's Fig. 4b-c from a study over ``alpha`` (as an
  :class:`analysis.alpha_sweep.AlphaSweepResult`, drawn by the same figure).
- :func:`rank_designs`: the best cells for a target metric (largest first, or smallest with
  ``min:``), each with its parameters.

Only cells that ran within the study's accuracy (status ok) count; the others are reported.
SI throughout; units are the study file's (``StudyData.units``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from protocols.study import PARAMETERS
from protocols.studyfile import STATUS_FAILED, STATUS_INACCURATE, STATUS_OK, StudyData

__all__ = [
    "REDUCERS",
    "PhaseMap",
    "alpha_sweep_from_study",
    "default_axes",
    "format_ranking",
    "parse_condition",
    "phase_map",
    "rank_designs",
    "sampled",
    "select_cells",
    "varying_parameters",
]

REDUCERS = ("mean", "median", "max", "min")
#: at most this many distinct values make a parameter a grid axis; more are binned
_GRID_MAX = 64


@dataclass(frozen=True)
class PhaseMap:
    """A heat map: ``values [ny, nx]`` of ``metric`` over ``x [nx]`` and ``y [ny]`` (SI centres
    of the grid values or bins); NaN where no cell counted. ``fixed``: parameter -> the value
    used; ``reduced``: parameters marginalised with ``reduce``; ``cells``: cells counted;
    ``left_out``: cells that ran outside the accuracy asked for (or without an estimate);
    ``failed``: cells that failed, and ``failed_xy`` the map cells (x, y centres, SI) where at
    least one of those drawn would have sat; ``x_log``, ``y_log``: that axis is binned
    logarithmically (draw it on a log scale)."""

    metric: str
    unit: str
    x_name: str
    y_name: str
    x: NDArray[np.float64]
    y: NDArray[np.float64]
    values: NDArray[np.float64]
    fixed: dict[str, float]
    reduced: list[str]
    reduce: str
    cells: int
    left_out: int
    failed: int = 0
    failed_xy: tuple[tuple[float, float], ...] = ()
    x_log: bool = False
    y_log: bool = False


def varying_parameters(data: StudyData) -> list[str]:
    """Parameters (with ``amplitude``) that take more than one value, in the study's order."""
    return [n for n, v in data.parameters.items() if np.unique(v).size > 1]


def default_axes(data: StudyData) -> tuple[str, str]:
    """The first two varying parameters (x, y)."""
    vary = varying_parameters(data)
    if len(vary) < 2:
        raise ValueError(
            f"a phase diagram needs two parameters that vary; this study varies {vary or 'none'}"
        )
    return vary[0], vary[1]


def select_cells(
    data: StudyData, fixed: dict[str, float] | None = None, *, status: int = STATUS_OK
) -> tuple[NDArray[np.bool_], dict[str, float]]:
    """Cells that ran within accuracy (or have another ``status``) and sit at the ``fixed``
    values (the nearest value of each parameter the study holds, returned as used)."""
    keep = data.status == status
    used: dict[str, float] = {}
    for name, want in (fixed or {}).items():
        if name not in data.parameters:
            raise ValueError(
                f"--fix {name}: not a parameter of this study ({', '.join(data.parameters)})"
            )
        col = data.parameters[name]
        values = np.unique(col)
        if values.size > _GRID_MAX:
            raise ValueError(f"--fix {name}: sampled, not a grid; it can only be marginalised")
        nearest = float(values[np.argmin(np.abs(values - want))])
        used[name] = nearest
        keep = keep & (col == nearest)
    return keep, used


def sampled(data: StudyData) -> bool:
    """Whether the study drew its design points (a Latin hypercube) rather than a grid."""
    import yaml

    try:
        doc = yaml.safe_load(str(data.attrs.get("study_yaml", ""))) or {}
    except yaml.YAMLError:
        return False
    return isinstance(doc, dict) and isinstance(doc.get("sampling"), dict)


def _axis(
    values: NDArray[np.float64], bins: int, name: str, drawn: bool = False
) -> tuple[NDArray[Any], NDArray[Any], bool]:
    """(centres, index of each cell, whether the bins are logarithmic) of one axis: distinct
    values, or ``bins`` bins. A drawn axis (a Latin hypercube's) is binned once it has more
    distinct values than ``bins`` (40 samples were 40 slivers); a grid's once it has more than
    ``_GRID_MAX``."""
    distinct = np.unique(values)
    if distinct.size <= (bins if drawn else _GRID_MAX):
        return distinct, np.searchsorted(distinct, values), False
    lo, hi = float(values.min()), float(values.max())
    log = name in PARAMETERS and lo > 0 and hi / lo > 10
    edges = np.geomspace(lo, hi, bins + 1) if log else np.linspace(lo, hi, bins + 1)
    centres = np.sqrt(edges[1:] * edges[:-1]) if log else 0.5 * (edges[1:] + edges[:-1])
    idx = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, bins - 1)
    return centres, idx, log


def phase_map(
    data: StudyData,
    metric: str,
    x: str | None = None,
    y: str | None = None,
    *,
    fixed: dict[str, float] | None = None,
    reduce: str = "mean",
    bins: int = 16,
) -> PhaseMap:
    """``metric`` over parameters ``x`` and ``y`` (default: the first two that vary); see the
    module docstring. Raises ValueError (one line) for an unknown metric, parameter or reducer."""
    if metric not in data.metrics:
        raise ValueError(f"metric {metric!r}: this study holds {', '.join(data.metrics)}")
    if reduce not in REDUCERS:
        raise ValueError(f"reduce {reduce!r}: one of {', '.join(REDUCERS)}")
    if x is None or y is None:
        free = [n for n in varying_parameters(data) if n not in (fixed or {}) and n not in (x, y)]
        if x is None:
            if not free:
                raise ValueError("x: no other varied parameter to draw along x")
            x = free.pop(0)
        if y is None:
            if not free:
                raise ValueError("y: no other varied parameter to draw along y")
            y = free.pop(0)
    for name in (x, y):
        if name not in data.parameters:
            raise ValueError(
                f"{name!r}: not a parameter of this study ({', '.join(data.parameters)})"
            )
    if x == y:
        raise ValueError("x and y: two different parameters")
    fixed = {k: v for k, v in (fixed or {}).items() if k not in (x, y)}
    keep, used = select_cells(data, fixed)
    drawn = sampled(data)
    if drawn:  # about one design point a map cell: bins per axis ~ sqrt(design points)
        bins = min(bins, max(2, round(math.sqrt(np.unique(data.point).size))))
    xc, xi, x_log = _axis(data.parameters[x], bins, x, drawn and x != "amplitude")
    yc, yi, y_log = _axis(data.parameters[y], bins, y, drawn and y != "amplitude")
    # counted where the map is drawn (the fixed values), as the cells it shows
    at_fixed, _ = select_cells(data, fixed, status=STATUS_FAILED)
    left_out = int(np.sum(select_cells(data, fixed, status=STATUS_INACCURATE)[0]))
    hit = np.unique(yi[at_fixed] * xc.size + xi[at_fixed])
    failed_xy = tuple((float(xc[k % xc.size]), float(yc[k // xc.size])) for k in hit)
    vals = data.metrics[metric]
    keep = keep & np.isfinite(vals)
    grid = np.full((yc.size, xc.size), np.nan)
    funcs: dict[str, Callable[..., Any]] = {
        "mean": np.mean, "median": np.median, "max": np.max, "min": np.min
    }  # fmt: skip
    func = funcs[reduce]
    flat = yi[keep] * xc.size + xi[keep]
    v = vals[keep]
    order = np.argsort(flat, kind="stable")
    flat, v = flat[order], v[order]
    starts = np.flatnonzero(np.r_[True, flat[1:] != flat[:-1]]) if flat.size else flat
    for s, e in zip(starts, [*starts[1:], flat.size], strict=False):
        grid.flat[flat[s]] = float(func(v[s:e]))
    reduced = [n for n in varying_parameters(data) if n not in (x, y) and n not in used]
    return PhaseMap(
        metric, data.units.get(metric, ""), x, y, xc, yc, grid, used, reduced, reduce,
        int(keep.sum()), left_out, int(at_fixed.sum()), failed_xy, x_log, y_log,
    )  # fmt: skip


def _target(target: str) -> tuple[str, bool]:
    name, largest = target, True
    for prefix, big in (("max:", True), ("min:", False)):
        if target.startswith(prefix):
            name, largest = target[len(prefix) :], big
    return name, largest


def parse_condition(text: str) -> tuple[str, str, float]:
    """``"transmission_ltr>0.01"`` -> ``("transmission_ltr", ">", 0.01)`` (SI value)."""
    for op in (">=", "<=", ">", "<"):
        name, sep, value = text.partition(op)
        if sep:
            try:
                return name.strip(), op, float(value)
            except ValueError:
                break
    raise ValueError(f"condition {text!r}: write METRIC>VALUE or METRIC<VALUE (SI)")


def rank_designs(
    data: StudyData,
    target: str,
    *,
    top: int = 10,
    fixed: dict[str, float] | None = None,
    where: list[tuple[str, str, float]] | None = None,
) -> list[dict[str, float]]:
    """The ``top`` cells for ``target`` (a metric; ``min:NAME`` for the smallest) among those
    meeting every ``where`` condition (:func:`parse_condition`), each as ``{"cell", "rank",
    parameters..., target, other metrics...}`` (SI)."""
    name, largest = _target(target)
    if name not in data.metrics:
        raise ValueError(f"target {name!r}: one of the study's metrics ({', '.join(data.metrics)})")
    keep, _ = select_cells(data, fixed)
    for metric, op, value in where or []:
        if metric not in data.metrics:
            raise ValueError(f"condition on {metric!r}: one of {', '.join(data.metrics)}")
        col = data.metrics[metric]
        with np.errstate(invalid="ignore"):
            keep = keep & {">": col > value, "<": col < value, ">=": col >= value,
                           "<=": col <= value}[op]  # fmt: skip
    vals = data.metrics[name]
    idx = np.flatnonzero(keep & np.isfinite(vals))
    order = idx[np.argsort(-vals[idx] if largest else vals[idx], kind="stable")][:top]
    rows = []
    for r, i in enumerate(order):
        row: dict[str, float] = {"rank": r + 1, "cell": int(i)}
        row.update({p: float(v[i]) for p, v in data.parameters.items()})
        row[name] = float(vals[i])
        row.update({m: float(v[i]) for m, v in data.metrics.items() if m != name})
        rows.append(row)
    return rows


def _fmt(name: str, value: float, units: dict[str, str]) -> str:
    unit = units.get(name, "")
    if not math.isfinite(value):
        return "-"  # as every other table prints a value it does not have
    scale = {"m": (1e3, "mm"), "N": (1.0, "N"), "Hz": (1e-3, "kHz")}
    if name == "amplitude" and unit == "m":
        return f"{value * 1e6:.3g} um"
    if unit in scale:
        k, u = scale[unit]
        return f"{value * k:.4g} {u}"
    if PARAMETERS.get(name) is not None and PARAMETERS[name].integer:
        return f"{value:.0f}"
    return f"{value:.4g}"


def format_ranking(
    rows: list[dict[str, float]], data: StudyData, target: str, extra: int = 3
) -> str:
    """The ranking as a text table: rank, cell, the varying parameters, the target and a few
    other metrics."""
    name, largest = _target(target)
    params = varying_parameters(data) or list(data.parameters)
    others = [m for m in data.metrics if m != name][:extra]
    cols = ["rank", "cell", *params, name, *others]
    head = f"best designs for {'largest' if largest else 'smallest'} {name}"
    table = [cols] + [
        [str(int(r["rank"])), str(int(r["cell"]))]
        + [_fmt(c, r[c], data.units) for c in [*params, name, *others]]
        for r in rows
    ]
    widths = [max(len(row[i]) for row in table) for i in range(len(cols))]
    lines = [head] + [
        "  ".join(c.rjust(w) for c, w in zip(row, widths, strict=True)) for row in table
    ]
    return "\n".join(lines)


def alpha_sweep_from_study(data: StudyData, *, fixed: dict[str, float] | None = None) -> Any:
    """The paper's Fig. 4b-c from a study over ``alpha`` with ``record_spectra: true``: an
    :class:`analysis.alpha_sweep.AlphaSweepResult` at the ``fixed`` values of the other
    parameters (default: the largest amplitude, the first value of the rest)."""
    from analysis.alpha_sweep import AlphaSweepResult

    if "alpha" not in data.parameters or np.unique(data.parameters["alpha"]).size < 2:
        raise ValueError("the asymmetry sweep needs a study over alpha (two values or more)")
    if data.spectrum_freq_Hz is None or not data.spectra:
        raise ValueError("the asymmetry sweep needs the far-end spectra: record_spectra: true")
    for d in data.directions:
        for m in (f"peak_frequency_{d}", f"transmission_{d}"):
            if m not in data.metrics:
                raise ValueError(f"the asymmetry sweep needs the metric {m.rsplit('_', 1)[0]}")
    chosen = dict(fixed or {})
    for name in varying_parameters(data):
        if name != "alpha" and name not in chosen:
            col = data.parameters[name]
            chosen[name] = float(col.max() if name == "amplitude" else col.min())
    # every cell that ran within accuracy: an alpha with no output peak keeps its spectra and
    # the other direction's peak (it was dropped whole when the first direction had none)
    keep, used = select_cells(data, chosen)
    idx = np.flatnonzero(keep)
    idx = idx[np.argsort(data.parameters["alpha"][idx], kind="stable")]
    if idx.size < 2:
        raise ValueError("fewer than two alphas ran within accuracy at the chosen values")
    from protocols.study import parse_study

    study = parse_study(str(data.attrs["study_yaml"]), str(data.path)).study
    inputs = {d: study.drive.carrier(d) for d in data.directions}
    kind = str(data.attrs.get("amplitude_kind", "displacement"))
    amp = used.get("amplitude", float(data.parameters["amplitude"][idx[0]]))
    result = AlphaSweepResult(
        alphas=data.parameters["alpha"][idx],
        alpha_actual=data.metrics["alpha_actual"][idx],
        inputs_Hz=inputs,
        amplitude=(kind, amp),
        duration_s=study.simulation.duration,
        freq_Hz=data.spectrum_freq_Hz,
    )
    for d in data.directions:
        result.magnitude[d] = np.asarray(data.spectra[d][idx], dtype=np.float64)
        result.output_Hz[d] = data.metrics[f"peak_frequency_{d}"][idx]
        result.expected_Hz[d] = data.metrics[f"f_edge_{d}"][idx]
        result.transmission[d] = data.metrics[f"transmission_{d}"][idx]
    return result
