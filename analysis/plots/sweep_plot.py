"""Amplitude sweep (paper Fig. 2d-e): far-cylinder spectrum against amplitude for each
direction, and the detuning per amplitude between them."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import QuadMesh
from matplotlib.figure import Figure

from analysis.plots.quasi_bands import DIRECTION_COLOURS
from analysis.plots.style import (
    MISSING_AT,
    add_gap_background,
    amplitude_scale,
    cell_edges,
    gap_legend_handle,
    mark_missing,
    masked_cmap,
    new_figure,
    style,
)
from analysis.spectra import spectrum_db
from analysis.sweep import AmplitudeSweep

__all__ = ["plot_amplitude_sweep"]

MARKERS = {"ltr": "o-", "rtl": "s--"}


def _log_amplitudes(a: np.ndarray) -> bool:
    return bool(a.size > 1 and np.all(a > 0) and a.max() / a.min() > 10)


def _map(ax: Axes, sw: AmplitudeSweep) -> QuadMesh:
    add_gap_background(ax)
    factor, unit = amplitude_scale(sw.amplitudes, sw.amplitude_units)
    amps = sw.amplitudes / factor
    log = _log_amplitudes(amps)
    # per unit drive: a linear chain gives the same row at every amplitude, so what brightens
    # with amplitude is what the nonlinearity lets through
    amp = np.where(np.abs(sw.amplitudes) > 0, np.abs(sw.amplitudes), np.nan)
    per_drive = sw.magnitude / amp[:, None]
    mesh = ax.pcolormesh(
        cell_edges(sw.freq_Hz / 1e3),
        cell_edges(amps, log=log),
        spectrum_db(per_drive),
        cmap=masked_cmap("viridis"),
        vmin=-40,
        vmax=0,
        shading="flat",
        rasterized=True,
    )
    colour = DIRECTION_COLOURS.get(sw.direction, "k")
    ok = np.isfinite(sw.output_Hz)
    ax.plot(sw.output_Hz[ok] / 1e3, amps[ok], "o", mfc="white", mec="k", ms=5, label="output peak")
    f_in = float(np.nanmedian(sw.input_Hz))
    ax.axvline(f_in / 1e3, color="white", ls="--", lw=1, label=f"input {f_in / 1e3:.2f} kHz")
    ax.axvline(sw.expected_Hz / 1e3, color=colour, ls=":", lw=1.5, label="far-cylinder edge")
    ax.plot(
        sw.expected_Hz / 1e3, amps.max(), "*", ms=16, color=colour, mec="k", clip_on=False, zorder=5
    )
    if log:
        ax.set_yscale("log")
    ax.set_xlabel("frequency (kHz)")
    ax.set_ylabel(f"drive amplitude ({unit})")
    ax.set_title(f"{sw.direction.upper()}: far cylinder #{sw.far}")
    handles, _ = ax.get_legend_handles_labels()
    if not np.all(sw.far_measured):  # a measured row is drawn, with or without a peak
        handles.append(gap_legend_handle())
    ax.legend(handles=handles, loc="lower left", fontsize=8, framealpha=0.85)
    return mesh


def plot_amplitude_sweep(sweeps: Mapping[str, AmplitudeSweep]) -> Figure:
    """Far-cylinder spectrum maps for each direction (|V_far| per unit drive amplitude, dB re
    the largest, so a linear chain would give identical rows) and, in the middle panel, the
    detuning (output peak - input, kHz) against amplitude, each point labelled with its
    transmission gain over the smallest amplitude, the far-cylinder edges dotted."""
    order = [d for d in ("ltr", "rtl") if d in sweeps]
    panels: list[str] = []
    if "ltr" in order:
        panels.append("ltr")
    panels.append("detuning")
    if "rtl" in order:
        panels.append("rtl")
    ratios = [3 if p != "detuning" else 2 for p in panels]
    with style():
        fig, axs = new_figure(
            1, len(panels), figsize=(4.0 * len(panels), 4.6), gridspec_kw={"width_ratios": ratios}
        )
        mesh = None
        for ax, p in zip(axs[0], panels, strict=True):
            if p != "detuning":
                mesh = _map(ax, sweeps[p])
                continue
            ax.axvline(0, color="0.5", lw=0.8)
            units = {sweeps[d].amplitude_units for d in order}
            same = len(units) == 1
            factor, unit = amplitude_scale(
                np.concatenate([sweeps[d].amplitudes for d in order]), units.pop()
            )
            for d in order:
                sw = sweeps[d]
                colour = DIRECTION_COLOURS.get(d, "k")
                ok = np.isfinite(sw.detuning_Hz)
                f = factor if same else 1.0
                ax.plot(
                    sw.detuning_Hz[ok] / 1e3,
                    sw.amplitudes[ok] / f,
                    MARKERS.get(d, "o-"),
                    color=colour,
                    mfc="none" if d == "rtl" else colour,
                    label=d.upper() if same else f"{d.upper()} ({sw.amplitude_units})",
                )
                for x, y, g in zip(
                    sw.detuning_Hz[ok] / 1e3,
                    sw.amplitudes[ok] / f,
                    sw.transmission_gain[ok],
                    strict=True,
                ):
                    # a gain that cannot be read (the entry point failed) says so
                    ax.annotate(
                        f"×{'≥' if sw.reference_is_bound else ''}{g:.3g}"
                        if np.isfinite(g)
                        else "× n/a",
                        (x, y),
                        textcoords="offset points",
                        xytext=(0, 6),
                        ha="center",
                        fontsize=8,
                        color=colour,
                    )
                gone = ~sw.far_measured  # measured without a peak is no missing point
                mark_missing(
                    ax, sw.amplitudes[gone] / f, colour, along="y",
                    label=f"{d.upper()} far cylinder failed or not measured",
                    at=MISSING_AT.get(d, 0.03),
                )  # fmt: skip
                f_in = float(np.nanmedian(sw.input_Hz))
                if np.isfinite(sw.expected_Hz):  # none without a local-resonance band
                    ax.axvline((sw.expected_Hz - f_in) / 1e3, color=colour, ls=":", lw=1.5)
            every = np.concatenate(
                [sweeps[d].amplitudes / (factor if same else 1.0) for d in order]
            )
            if _log_amplitudes(every):  # the limits from every direction, before the scale:
                # with no point drawn (every far record at the noise floor) the log scale had
                # no data and failed
                ax.set_ylim(float(every.min()) / 1.5, float(every.max()) * 1.5)
                ax.set_yscale("log")
            ax.set_xlabel("detuning f_out - f_in (kHz)")
            ax.set_ylabel(f"drive amplitude ({unit})" if same else "drive amplitude")
            ax.set_title("detuning; ×: transmission gain")
            ax.legend(loc="best", fontsize=8)
        if mesh is not None:
            fig.colorbar(mesh, ax=axs[0, -1], label="|V_far| / drive amplitude (dB re max)")
    return fig
