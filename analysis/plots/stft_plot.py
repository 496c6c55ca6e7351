"""Short-time Fourier transforms of a few cylinders along the chain, and the ridge."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from analysis.plots.style import add_gap_background, cell_edges, masked_cmap, new_figure, style
from analysis.spectra import spectrum_db
from analysis.stft import Stft, ridge_frequency

__all__ = ["plot_stft"]


def plot_stft(
    panels: Sequence[tuple[int, Stft]],
    f_range_Hz: tuple[float, float],
    title: str = "",
    band_edges_Hz: Sequence[tuple[float, float]] | None = None,
) -> Figure:
    """One panel per ``(cylinder number, Stft of its velocity)``: |STFT| in dB re the largest
    over all panels (-40..0) against time (ms, x) and frequency (kHz, y), with the ridge
    (white dots) and, if given, the cylinder's local band edges (dotted)."""
    n = len(panels)
    ncols = min(3, max(1, n))
    nrows = max(1, -(-n // ncols))
    finite = [float(np.nanmax(s.magnitude)) for _, s in panels if np.any(np.isfinite(s.magnitude))]
    ref = max(finite, default=1.0)
    with style():
        fig, axs = new_figure(
            nrows, ncols, figsize=(3.6 * ncols, 2.9 * nrows), sharex=True, sharey=True
        )
        mesh = None
        for k, ax in enumerate(axs.flat):
            if k >= n:
                ax.set_visible(False)
                continue
            number, s = panels[k]
            add_gap_background(ax)
            sel = (s.freq_Hz >= f_range_Hz[0]) & (s.freq_Hz <= f_range_Hz[1])
            mesh = ax.pcolormesh(
                cell_edges(s.time_s * 1e3),
                cell_edges(s.freq_Hz[sel] / 1e3),
                spectrum_db(s.magnitude[sel], ref),
                cmap=masked_cmap("inferno"),
                vmin=-40,
                vmax=0,
                shading="flat",
                rasterized=True,
            )
            ridge = ridge_frequency(s, *f_range_Hz, rel_threshold=0.1)
            ax.plot(s.time_s * 1e3, ridge / 1e3, ".", color="white", ms=2)
            if band_edges_Hz is not None:
                lo, hi = band_edges_Hz[k]
                for f in (lo, hi):
                    ax.axhline(f / 1e3, color="cyan", ls=":", lw=1)
            ax.set_ylim(f_range_Hz[0] / 1e3, f_range_Hz[1] / 1e3)
            ax.set_title(f"cylinder #{number}")
            if k % ncols == 0:
                ax.set_ylabel("frequency (kHz)")
            if k // ncols == nrows - 1:
                ax.set_xlabel("time (ms)")
        if mesh is not None:
            fig.colorbar(mesh, ax=axs, label="|STFT| (dB re max)", shrink=0.8)
        if title:
            fig.suptitle(title)
    return fig
