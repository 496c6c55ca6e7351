"""Design-study figures: a phase diagram (heat map of one metric over two parameters)."""

from __future__ import annotations

import numpy as np
from matplotlib.colors import LogNorm, Normalize
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter

from analysis.plots.style import (
    FAILED_COLOUR,
    add_gap_background,
    cell_edges,
    masked_cmap,
    new_figure,
    style,
)
from analysis.study_maps import PhaseMap

__all__ = ["axis_label", "display_scale", "plot_phase_map"]

#: metrics drawn on a log colour scale (ratios of energies)
_LOG = ("transmission", "asymmetry_ratio", "efficiency")


def display_scale(name: str, unit: str) -> tuple[float, str]:
    """(factor, unit) to show an SI value of ``name``: mm, um for amplitudes, kHz, %."""
    if name == "amplitude" and unit == "m":
        return 1e6, "um"
    if name.startswith(("detuning", "edge_fraction")):
        return (100.0, "%") if name.startswith("detuning") else (1.0, "")
    return {"m": (1e3, "mm"), "Hz": (1e-3, "kHz"), "N": (1.0, "N")}.get(unit, (1.0, unit))


def axis_label(name: str, unit: str) -> str:
    _, u = display_scale(name, unit)
    label = {"preload": "pre-compression F0", "n_cylinders": "cylinders N",
             "alpha": "asymmetry factor α"}.get(name, name.replace("_", " "))  # fmt: skip
    return f"{label} ({u})" if u else label


def plot_phase_map(pm: PhaseMap, units: dict[str, str]) -> Figure:
    """One heat map: x and y the two parameters, colour the metric (log scale for energy
    ratios, floored at 1e-4 of the largest); grey hatching where no cell counted; the fixed
    and marginalised parameters in the title."""
    kx, _ = display_scale(pm.x_name, units.get(pm.x_name, ""))
    ky, _ = display_scale(pm.y_name, units.get(pm.y_name, ""))
    kv, _ = display_scale(pm.metric, pm.unit)
    vals = pm.values * kv
    finite = vals[np.isfinite(vals)]
    norm: Normalize
    positive = finite[finite > 0]
    if pm.metric.startswith(_LOG) and positive.size:
        # energy ratios span decades: log colours, floored at 1e-4 of the largest (0 and
        # anything below the floor drawn in the floor's colour)
        top = float(positive.max())
        low = max(float(positive.min()), top * 1e-4)
        vals = np.where(np.isfinite(vals), np.maximum(vals, low), np.nan)
        norm = LogNorm(vmin=low, vmax=max(top, low * 1.01))
    else:
        norm = Normalize(
            vmin=float(finite.min()) if finite.size else 0.0,
            vmax=float(finite.max()) if finite.size else 1.0,
        )
    with style():
        fig, axs = new_figure(1, 1, figsize=(5.6, 4.4))
        ax = axs[0, 0]
        add_gap_background(ax)
        mesh = ax.pcolormesh(
            cell_edges(pm.x * kx, log=pm.x_log), cell_edges(pm.y * ky, log=pm.y_log), vals,
            cmap=masked_cmap("viridis"), norm=norm, shading="flat",
        )  # fmt: skip
        plain = FuncFormatter(lambda v, _: f"{v:g}")
        for on, axis, scale in ((pm.x_log, ax.xaxis, ax.set_xscale),
                                (pm.y_log, ax.yaxis, ax.set_yscale)):  # fmt: skip
            if on:  # log bins on a log axis, ticks as plain numbers
                scale("log")
                axis.set_major_formatter(plain)
                axis.set_minor_formatter(plain)
        ax.set_xlabel(axis_label(pm.x_name, units.get(pm.x_name, "")))
        ax.set_ylabel(axis_label(pm.y_name, units.get(pm.y_name, "")))
        fig.colorbar(mesh, ax=ax, label=axis_label(pm.metric, pm.unit))
        parts = []
        for name, v in pm.fixed.items():
            k, u = display_scale(name, units.get(name, ""))
            parts.append(f"{name} = {v * k:.4g} {u}".strip())
        if pm.reduced:
            parts.append(f"{pm.reduce} over {', '.join(pm.reduced)}")
        if pm.failed:
            parts.append(f"{pm.failed} cells failed (x)")
        if pm.left_out:
            parts.append(f"{pm.left_out} cells off accuracy left out")
        if pm.failed_xy:  # a failed cell is not a gap like one not run: a cross on its cell
            fx, fy = (np.array(v) for v in zip(*pm.failed_xy, strict=True))
            ax.plot(fx * kx, fy * ky, "x", color=FAILED_COLOUR, ms=7, mew=2, ls="none",
                    label="failed cell", zorder=5)  # fmt: skip
            ax.legend(loc="upper right", fontsize=7, framealpha=0.85)
        ax.set_title(pm.metric + ("\n" + "; ".join(parts) if parts else ""), fontsize=9)
    return fig
