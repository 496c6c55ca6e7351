"""Spatial-frequency map (paper Fig. 3) with the far cylinder's spectrum beside it."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from analysis.bands import linear_limit_cylinder
from analysis.plots.quasi_bands import DIRECTION_COLOURS
from analysis.plots.style import (
    DARK_EDGE,
    add_gap_background,
    cell_edges,
    gap_legend_handle,
    masked_cmap,
    new_figure,
    on_every_cylinder,
    style,
)
from analysis.spatial import SpatialFrequencyMap
from analysis.spectra import Spectrum, spectrum_db

__all__ = ["plot_spatial_frequency"]


def plot_spatial_frequency(
    smap: SpatialFrequencyMap,
    direction: str,
    f_in_Hz: float,
    onset_Hz: np.ndarray,
    cutoff_Hz: np.ndarray,
    far: int,
    drive: Spectrum | None = None,
    title: str = "",
) -> Figure:
    """Map of |V| (dB re its max, -40..0) against cylinder (x) and frequency (kHz, y), circles
    at each cylinder's peak, the local band edges (green dotted), the linear limit (white
    dashed), and at the side the far cylinder ``far`` (1-based) spectrum with the drive's."""
    colour = DIRECTION_COLOURS.get(direction, "k")
    f_khz = smap.freq_Hz / 1e3
    with style():
        fig, axs = new_figure(
            1, 2, figsize=(8.0, 4.8), sharey=True, gridspec_kw={"width_ratios": [3, 1]}
        )
        ax, side = axs[0, 0], axs[0, 1]
        add_gap_background(ax)
        x_edges, db = on_every_cylinder(smap.cylinders, spectrum_db(smap.magnitude))
        mesh = ax.pcolormesh(
            x_edges,
            cell_edges(f_khz),
            db.T,
            cmap=masked_cmap("magma"),
            vmin=-40,
            vmax=0,
            shading="flat",
            rasterized=True,
        )
        fig.colorbar(mesh, ax=side, label="|V| (dB re max)")
        ok = np.isfinite(smap.peak_Hz)
        ax.plot(
            smap.cylinders[ok],
            smap.peak_Hz[ok] / 1e3,
            "o",
            mfc="none",
            mec="cyan",
            ms=6,
            label="peak per cylinder",
        )
        n = len(onset_Hz)
        xs = np.arange(1, n + 1)
        ax.plot(xs, onset_Hz / 1e3, ":", color="lime", lw=1.4, label="local band edges")
        ax.plot(xs, cutoff_Hz / 1e3, ":", color="lime", lw=1.4)
        ax.axhline(
            f_in_Hz / 1e3, color=colour, ls="--", lw=1, label=f"input {f_in_Hz / 1e3:.2f} kHz"
        )
        limit = linear_limit_cylinder(f_in_Hz, direction, onset_Hz, cutoff_Hz)
        if limit is not None:
            ax.axvline(limit, color="white", ls="--", lw=1.2, label=f"linear limit #{limit}",
                       path_effects=DARK_EDGE)  # fmt: skip
        ax.set_ylim(f_khz[0], f_khz[-1])
        ax.set_xlim(0.5, max(n, int(smap.cylinders.max())) + 0.5)
        ax.set_xlabel("cylinder number")
        ax.set_ylabel("frequency (kHz)")
        ax.set_title(title or f"{direction.upper()} spatial-frequency map")
        handles, _ = ax.get_legend_handles_labels()
        if not np.all(ok) or np.unique(smap.cylinders).size < n:  # a gap shows
            handles.append(gap_legend_handle())
        ax.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.85)
        hits = np.nonzero(smap.cylinders == far)[0]
        if hits.size and np.all(np.isfinite(smap.magnitude[hits[0]])):
            m = smap.magnitude[hits[0]]
            side.plot(m / np.max(m), f_khz, color=colour, label=f"#{far}")
        else:
            add_gap_background(side)
        if drive is not None and np.all(np.isfinite(drive.magnitude)):
            dm = np.interp(smap.freq_Hz, drive.freq_Hz, drive.magnitude)
            side.plot(dm / np.max(dm), f_khz, color="k", lw=1, label="drive")
        side.set_xlim(0, 1.05)
        side.set_xlabel("|V| (norm.)")
        side.set_title(f"far cylinder #{far}")
        if side.get_legend_handles_labels()[0]:
            side.legend(loc="lower right", fontsize=8)
    return fig
