"""Quasi-band diagram (paper Fig. 2c): onset and cutoff per cylinder, gaps shaded, inputs as
arrows, expected outputs as stars."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from analysis.bands import (
    band_edges,
    expected_output_Hz,
    linear_limit_cylinder,
    resonance_band_index,
)
from analysis.plots.style import new_figure, style
from protocols.runfile import ChainInfo

__all__ = ["DIRECTION_COLOURS", "plot_quasi_bands"]

#: colour of each direction in every figure
DIRECTION_COLOURS = {"ltr": "tab:red", "rtl": "tab:blue"}


def plot_quasi_bands(
    chain: ChainInfo, inputs: Sequence[tuple[str, float]] = (), title: str | None = None
) -> Figure:
    """Quasi-band diagram of ``chain``; ``inputs`` is ``[(direction, f_in_Hz), ...]``.

    y: frequency in kHz around the first local-resonance band; x: cylinder number. White:
    pass bands; grey: gaps between consecutive stored bands; dots: band edges.
    """
    onset = np.atleast_2d(chain.onset_Hz) / 1e3
    cutoff = np.atleast_2d(chain.cutoff_Hz) / 1e3
    n, n_bands = onset.shape
    x = np.arange(1, n + 1)
    b_lr = resonance_band_index(chain)
    lo_lr, hi_lr = band_edges(chain, b_lr)
    f_ins = [f / 1e3 for _, f in inputs]
    y_lo = 0.8 * min([float(lo_lr.min()) / 1e3, *f_ins])
    y_hi = 1.15 * max([float(hi_lr.max()) / 1e3, *f_ins])
    with style():
        fig, axs = new_figure(figsize=(6.5, 4.5))
        ax = axs[0, 0]
        ax.set_facecolor("white")
        for b in range(n_bands - 1):
            ax.fill_between(
                x, cutoff[:, b], onset[:, b + 1], step="mid", color="0.75", lw=0, zorder=0
            )
        for b in range(n_bands):
            kw = {"ms": 3, "zorder": 3}
            ax.plot(x, onset[:, b], "o", color="k", **kw, label="onset (q = 0)" if b == 0 else None)
            ax.plot(
                x,
                cutoff[:, b],
                "s",
                color="k",
                mfc="white",
                **kw,
                label="cutoff (q = π)" if b == 0 else None,
            )
        for direction, f_in in inputs:
            colour = DIRECTION_COLOURS.get(direction, "k")
            stop = linear_limit_cylinder(f_in, direction, lo_lr, hi_lr)
            start = 1 if direction == "ltr" else n
            end = stop if stop is not None else (n if direction == "ltr" else 1)
            ax.annotate(
                "",
                xy=(end, f_in / 1e3),
                xytext=(start, f_in / 1e3),
                arrowprops={"arrowstyle": "-|>", "color": colour, "lw": 2},
                zorder=4,
            )
            ax.text(
                start,
                f_in / 1e3,
                f" {direction.upper()} {f_in / 1e3:.2f} kHz ",
                color=colour,
                va="bottom",
                ha="left" if direction == "ltr" else "right",
            )
            f_out = expected_output_Hz(f_in, direction, lo_lr, hi_lr)
            far = n if direction == "ltr" else 1
            ax.plot(far, f_out / 1e3, "*", ms=14, color=colour, mec="k", zorder=5)
        ax.set_xlim(0.5, n + 0.5)
        ax.set_ylim(y_lo, y_hi)
        ax.set_xlabel("cylinder number")
        ax.set_ylabel("frequency (kHz)")
        ax.set_title(title or "Quasi-band diagram (grey: gaps; stars: expected output)")
        ax.legend(loc="upper right", framealpha=0.9)
    return fig
