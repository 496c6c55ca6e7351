"""Before and after a calibration: measured linear spectra against the model at the start values
and at the fitted values, a few cylinders along the chain, both directions."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from analysis.plots.quasi_bands import DIRECTION_COLOURS
from analysis.plots.style import new_figure, style

__all__ = ["plot_calibration"]


def plot_calibration(
    spectra: Mapping[str, Mapping[str, NDArray[np.float64]]], panels: int = 4
) -> Figure:
    """One row per direction, ``panels`` cylinders spread from the entry; the smallest
    amplitude's spectra: measured (colour), model at the start (grey dotted) and fitted (black
    dashed). ``spectra``: :func:`analysis.calibrate.fit_spectra`."""
    dirs = list(spectra)
    with style():
        fig, axs = new_figure(
            len(dirs), panels, figsize=(3.1 * panels, 2.7 * len(dirs)), sharex=True
        )
        for i, d in enumerate(dirs):
            s = spectra[d]
            cyl = s["cylinders"].astype(int)
            ok = np.flatnonzero(s["mask"][0] > 0)
            order = ok if d == "ltr" else ok[::-1]
            picks = order[np.linspace(0, len(order) - 1, min(panels, len(order))).astype(int)]
            f = s["freq_Hz"] / 1e3
            colour = DIRECTION_COLOURS.get(d, "k")
            for j in range(panels):
                ax = axs[i, j]
                if j >= len(picks):
                    ax.set_visible(False)
                    continue
                c = int(picks[j])
                ax.plot(f, s["measured"][0, c] * 1e9, color=colour, lw=1.3, label="measured")
                ax.plot(f, s["start"][0, c] * 1e9, ":", color="grey", lw=1.2, label="start")
                ax.plot(f, s["fitted"][0, c] * 1e9, "--", color="k", lw=1.0, label="fitted")
                ax.set_title(f"{d.upper()} cylinder #{cyl[c]}", fontsize=9)
                if i == len(dirs) - 1:
                    ax.set_xlabel("frequency (kHz)")
                if j == 0:
                    ax.set_ylabel("|V| (nm)")
        axs[0, 0].legend(fontsize=8)
        fig.suptitle("linear points, smallest amplitude: measured, model at start and fitted")
    return fig
