"""Asymmetry sweep figure (paper Fig. 4b-c): far-cylinder spectrum against alpha, as fractional
detuning, with the predicted far-cylinder edge."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from analysis.alpha_sweep import AlphaSweepResult
from analysis.display import amplitude_label
from analysis.plots.quasi_bands import DIRECTION_COLOURS
from analysis.plots.style import (
    DARK_EDGE,
    add_gap_background,
    cell_edges,
    masked_cmap,
    new_figure,
    style,
)
from analysis.spectra import spectrum_db

__all__ = ["plot_alpha_sweep"]


def _amp_text(amplitude: tuple[str, float]) -> str:
    kind, value = amplitude
    return amplitude_label(value, "m" if kind == "displacement" else "N")


def plot_alpha_sweep(result: AlphaSweepResult) -> Figure:
    """One panel per direction: x alpha, y fractional detuning (f - f_in)/f_in in %, colour the
    far cylinder's |V| in dB re the largest of that direction (-40..0); circles: output peak
    (white where it converts, grey where the verdict is filtering or none, see
    :func:`analysis.alpha_sweep.alpha_verdict`); plus: the linear run's peak; dotted: the
    predicted edge (cutoff of #N for LTR, onset of #1 for RTL); hatched grey: alphas where the
    bands overlap (the one-band picture fails, no output peak drawn)."""
    dirs = list(result.output_Hz)
    with style():
        fig, axs = new_figure(1, len(dirs), figsize=(5.2 * len(dirs), 5.4))
        mesh = None
        for ax, d in zip(axs.flat, dirs, strict=False):
            add_gap_background(ax)
            f_in = result.inputs_Hz[d]
            det = (result.freq_Hz - f_in) / f_in * 100.0
            mesh = ax.pcolormesh(
                cell_edges(result.alphas),
                cell_edges(det),
                spectrum_db(result.magnitude[d]).T,
                cmap=masked_cmap("viridis"),
                vmin=-40,
                vmax=0,
                shading="flat",
                rasterized=True,
            )
            colour = DIRECTION_COLOURS.get(d, "k")
            det_out = result.fractional_detuning(d) * 100
            converts = np.array([v in ("down", "up") for v in result.verdicts(d)])
            ax.plot(
                result.alphas[converts],
                det_out[converts],
                "o",
                mfc="none",
                mec="white",
                ms=7,
                path_effects=DARK_EDGE,
                label="output peak: converts",
            )
            if np.any(~converts & np.isfinite(det_out)):
                ax.plot(
                    result.alphas[~converts],
                    det_out[~converts],
                    "o",
                    mfc="none",
                    mec="0.6",
                    ms=7,
                    label="output peak: no conversion",
                )
            if d in result.linear_output_Hz and result.reference_amplitude is not None:
                ax.plot(
                    result.alphas,
                    result.linear_fractional_detuning(d) * 100,
                    "+",
                    color="white",
                    ms=7,
                    mew=1.5,
                    path_effects=DARK_EDGE,
                    label=f"linear peak ({_amp_text(result.reference_amplitude)})",
                )
            overlap = result.overlap()
            if overlap.any():
                edges = cell_edges(result.alphas)
                for j in np.flatnonzero(overlap):
                    ax.axvspan(
                        edges[j],
                        edges[j + 1],
                        facecolor="none",
                        hatch="//",
                        edgecolor="0.75",
                        lw=0,
                        label="bands overlap" if j == overlap.argmax() else None,
                    )
            ax.plot(
                result.alphas,
                result.expected_fractional_detuning(d) * 100,
                ":",
                color=colour,
                lw=2,
                marker="*",
                ms=9,
                label="predicted edge",
            )
            ax.axhline(0, color="0.7", lw=0.8)
            marks = np.concatenate(
                [result.fractional_detuning(d), result.expected_fractional_detuning(d)]
            )
            marks = marks[np.isfinite(marks)] * 100.0
            if marks.size:
                ax.set_ylim(min(-5.0, marks.min() - 8.0), max(5.0, marks.max() + 8.0))
            ax.set_xlabel("asymmetry factor α")
            ax.set_ylabel("fractional detuning Δf/f_in (%)")
            ax.set_title(f"{d.upper()} at {f_in / 1e3:.2f} kHz")
            ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), fontsize=7, ncol=2)
        if mesh is not None:
            fig.colorbar(mesh, ax=axs, label="|V| far cylinder (dB re max)", shrink=0.85)
    return fig
