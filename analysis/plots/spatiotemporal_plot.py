"""Spatiotemporal map: velocity envelope against cylinder and time."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

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
from analysis.spatiotemporal import SpatiotemporalMap
from analysis.spectra import spectrum_db

__all__ = ["plot_spatiotemporal"]


def plot_spatiotemporal(
    panels: Sequence[tuple[str, SpatiotemporalMap]],
    linear_limit: int | None = None,
    title: str = "",
    n_cylinders: int | None = None,
) -> Figure:
    """One panel per ``(label, map)``: envelope in dB re the panel's max (-40..0) against
    cylinder (x, 1 to ``n_cylinders``, hatched where not scanned) and time (ms, y); the linear
    limit cylinder as a dotted line."""
    n = max(1, len(panels))
    with style():
        fig, axs = new_figure(1, n, figsize=(4.2 * n, 4.6), sharey=True)
        mesh = None
        for ax, (label, m) in zip(axs[0], panels, strict=False):
            add_gap_background(ax)
            x_edges, db = on_every_cylinder(m.cylinders, spectrum_db(m.envelope))
            mesh = ax.pcolormesh(
                x_edges,
                cell_edges(m.time_s * 1e3),
                db.T,
                cmap=masked_cmap("viridis"),
                vmin=-40,
                vmax=0,
                shading="flat",
                rasterized=True,
            )
            if linear_limit is not None:
                ax.axvline(
                    linear_limit, color="w", ls=":", lw=1.5, label=f"linear limit #{linear_limit}",
                    path_effects=DARK_EDGE,
                )  # fmt: skip
            last = max(n_cylinders or 0, int(m.cylinders.max()))
            handles, _ = ax.get_legend_handles_labels()
            if np.isnan(db).any() or np.unique(m.cylinders).size < last:  # a gap shows
                handles.append(gap_legend_handle())
            if handles:
                ax.legend(handles=handles, loc="upper right", fontsize=8)
            ax.set_xlim(0.5, last + 0.5)
            ax.set_xlabel("cylinder number")
            ax.set_title(label)
        axs[0, 0].set_ylabel("time from trigger (ms)")
        if mesh is not None:
            fig.colorbar(mesh, ax=axs, label="|v| envelope (dB re panel max)", shrink=0.85)
        if title:
            fig.suptitle(title)
    return fig
