"""Measured and predicted side by side, on the same axes and colour scales (``biafc compare``)."""

from __future__ import annotations

import math

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from analysis.compare import Comparison, DirectionComparison
from analysis.plots.quasi_bands import DIRECTION_COLOURS
from analysis.plots.style import (
    VERDICT_KINDS,
    add_gap_background,
    amplitude_label,
    amplitude_scale,
    cell_edges,
    mark_missing,
    masked_cmap,
    new_figure,
    on_every_cylinder,
    plot_by_verdict,
    style,
)
from analysis.spatial import SpatialFrequencyMap
from analysis.spectra import spectrum_db
from analysis.summary import summary_rows

__all__ = [
    "plot_compare_residuals",
    "plot_compare_spatial",
    "plot_compare_spectra",
    "plot_compare_sweep",
]

#: how each point state that is not compared is drawn
BAD_MARK = {"failed": ("X", "red"), "clipped": ("^", "orange"), "pending": ("o", "grey")}
#: what a legend calls each state (the other figures say "not measured", never "pending")
SHOWN = {"failed": "failed", "clipped": "clipped", "pending": "not measured"}


def plot_compare_spatial(
    measured: SpatialFrequencyMap,
    predicted: SpatialFrequencyMap,
    state: np.ndarray,
    onset_Hz: np.ndarray,
    cutoff_Hz: np.ndarray,
    f_in_Hz: float,
    title: str,
) -> Figure:
    """Two spatial-frequency maps (|V| in dB re the measured map's maximum, one colour scale),
    measured left and predicted right; cylinders whose point is failed, clipped or not measured
    are marked along the bottom (``state [C]``)."""
    finite = measured.magnitude[np.isfinite(measured.magnitude)]
    ref = float(finite.max()) if finite.size and finite.max() > 0 else None
    ref_name = "measured"
    if ref is None:  # nothing measured: the model's own maximum, and the label says so
        pf = predicted.magnitude[np.isfinite(predicted.magnitude)]
        ref = float(pf.max()) if pf.size and pf.max() > 0 else 1.0
        ref_name = "model"
    with style():
        fig, axs = new_figure(1, 2, figsize=(11.0, 4.6), sharey=True, sharex=True)
        mesh = None
        for ax, smap, name in ((axs[0, 0], measured, "measured"), (axs[0, 1], predicted, "model")):
            add_gap_background(ax)
            f_khz = smap.freq_Hz / 1e3
            x_edges, db = on_every_cylinder(smap.cylinders, spectrum_db(smap.magnitude, ref))
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
            xs = np.arange(1, len(onset_Hz) + 1)
            ax.plot(xs, onset_Hz / 1e3, ":", color="lime", lw=1.2, label="local band edges")
            ax.plot(xs, cutoff_Hz / 1e3, ":", color="lime", lw=1.2)
            ax.axhline(f_in_Hz / 1e3, color="white", ls="--", lw=0.8)
            for st, (marker, colour) in BAD_MARK.items():
                sel = state == st
                if np.any(sel):
                    ax.plot(
                        smap.cylinders[sel],
                        np.full(int(sel.sum()), f_khz[0] + 0.03 * (f_khz[-1] - f_khz[0])),
                        marker,
                        color=colour,
                        ms=7,
                        ls="none",
                        label=SHOWN[st],
                    )
            ax.set_ylim(f_khz[0], f_khz[-1])
            ax.set_xlim(0.5, max(len(onset_Hz), int(smap.cylinders.max())) + 0.5)
            ax.set_xlabel("cylinder number")
            ax.set_title(f"{name}: {title}")
        axs[0, 0].set_ylabel("frequency (kHz)")
        axs[0, 0].legend(loc="upper right", fontsize=8, framealpha=0.85)
        assert mesh is not None
        fig.colorbar(mesh, ax=list(axs[0]), label=f"|V| (dB re {ref_name} max)")
    return fig


def plot_compare_spectra(dc: DirectionComparison) -> Figure:
    """Far-cylinder spectra at every amplitude: measured (solid) and model (dashed) on the same
    axes, one panel per amplitude; panels of failed, clipped or unmeasured points say so."""
    ms, ps = dc.measured_sweep, dc.predicted_sweep
    n = len(ms.amplitudes)
    cols = min(4, n)
    rows = math.ceil(n / cols)
    colour = DIRECTION_COLOURS.get(dc.direction, "k")
    far_state = dc.state_of(ms.far)
    with style():
        # at least two panels wide: the title of one amplitude's figure was cut at both ends
        fig, axs = new_figure(rows, cols, figsize=(3.2 * max(cols, 2), 2.6 * rows))
        for a in range(rows * cols):
            ax: Axes = axs[a // cols, a % cols]
            if a >= n:
                ax.set_visible(False)
                continue
            f = ms.freq_Hz / 1e3
            if np.all(np.isfinite(ms.magnitude[a])):
                ax.plot(f, ms.magnitude[a] * 1e6, color=colour, lw=1.2, label="measured")
            else:
                add_gap_background(ax)
            ax.plot(f, ps.magnitude[a] * 1e6, "--", color="k", lw=1.0, label="model")
            ax.axvline(ms.expected_Hz / 1e3, color=colour, ls=":", lw=1)
            label = amplitude_label(float(ms.amplitudes[a]), ms.amplitude_units)
            st = str(far_state[a])
            if st == "ok" and ms.at_noise_floor[a]:
                st = "at the noise floor"
            ax.set_title(f"{label}" + ("" if st == "ok" else f" ({st})"), fontsize=9)
            if a // cols == rows - 1:
                ax.set_xlabel("frequency (kHz)")
            if a % cols == 0:
                ax.set_ylabel(f"#{ms.far} velocity spectrum |V(f)| (µm)")
        axs[0, 0].legend(fontsize=8)
        fig.suptitle(f"{dc.direction.upper()}: far cylinder #{ms.far}, measured and model")
    return fig


def plot_compare_sweep(cmp: Comparison) -> Figure:
    """Energy transmission (far / entry cylinder) and the far cylinder's spectral peak against
    amplitude, both directions: measured markers, model lines; amplitudes whose entry or far
    point is failed, clipped or not measured get the state's marker instead.

    The peaks, measured (circles) and model (squares on its line), are drawn as the regime
    figure draws them, by the verdict of :func:`analysis.summary.conversion_verdict` on their
    own sweep (:func:`analysis.summary.summary_rows`): filled where it converted, hollow in the
    direction's colour where undetermined, hollow grey where not; before, every peak was a
    filled dot, and a line that had not converted could not be told from one that had.

    The transmission is the far end's signal, as the regime figure's: where the measured far
    record's noise is known, its energy in the band where the signal can be less the noise's
    there (``signal_transmission``), and the model's in the same band
    (``predicted_signal``). A far record at the noise floor is a downward triangle at its
    upper bound (``transmission_bound``): before, its whole record's E_far/E_entry, the noise's,
    was drawn as measured (1.2e-2 at 10 nm against the model's 8e-5)."""
    with style():
        fig, axs = new_figure(1, 2, figsize=(11.0, 4.2))
        ax_t, ax_f = axs[0, 0], axs[0, 1]
        for d, dc in cmp.directions.items():
            ms, ps = dc.measured_sweep, dc.predicted_sweep
            colour = DIRECTION_COLOURS.get(d, "k")
            factor, unit = amplitude_scale(ms.amplitudes, ms.amplitude_units)
            x = ms.amplitudes / factor
            st = dc.sweep_state()
            floor = (st == "ok") & ms.at_noise_floor
            good = (st == "ok") & ~floor
            t_meas, t_model = ms.signal_transmission, dc.predicted_signal
            # a line and small dots: one amplitude is a line through one point, which drew
            # nothing though the legend named it
            ax_t.plot(x, t_model, ".-", color=colour, lw=1.2, ms=4,
                      label=f"{d.upper()} model")  # fmt: skip
            ax_t.plot(x[good], t_meas[good], "o", color=colour, label=f"{d.upper()} measured")
            if np.any(floor):
                ax_t.plot(x[floor], ms.transmission_bound[floor], "v", color=colour, mfc="none",
                          ms=8, ls="none",
                          label=f"{d.upper()} at the noise floor (at most)")  # fmt: skip
            # the far-end peak in the regime figure's verdict language (plots.style): filled
            # where the summary's verdict is a conversion, hollow in colour where the run
            # cannot tell, hollow grey where not; the model's sweep judged by the same rule
            ax_f.plot(x, ps.output_Hz / 1e3, "-", color=colour, lw=1.2)
            for series, sw, sel, marker, size in (
                ("model", ps, np.ones(x.size, dtype=bool), "s", 5),
                ("measured", ms, good, "o", 7),
            ):
                verdicts = np.array([r["conversion"] for r in summary_rows(sw)], dtype=object)
                labels = {k: f"{d.upper()} {series}, {k}" for k in VERDICT_KINDS}
                plot_by_verdict(ax_f, x[sel], sw.output_Hz[sel] / 1e3, verdicts[sel], marker,
                                colour, labels, ms=size)  # fmt: skip
            for name, (marker, mc) in BAD_MARK.items():  # unscanned: nothing to mark
                sel = st == name
                if np.any(sel):
                    yt = np.where(np.isfinite(t_meas[sel]), t_meas[sel], t_model[sel])
                    ax_t.plot(x[sel], yt, marker, color=mc, ms=8, ls="none", label=SHOWN[name])
                    yf = np.where(
                        np.isfinite(ms.output_Hz[sel]), ms.output_Hz[sel], ps.output_Hz[sel]
                    )
                    ax_f.plot(
                        x[sel], yf / 1e3, marker, color=mc, ms=8, ls="none", label=SHOWN[name]
                    )
            ax_f.axhline(ms.expected_Hz / 1e3, color=colour, ls=":", lw=1)
            ax_t.set_xlabel(f"amplitude ({unit})")
            ax_f.set_xlabel(f"amplitude ({unit})")
        xs_all = np.concatenate(
            [
                dc.measured_sweep.amplitudes
                / amplitude_scale(dc.measured_sweep.amplitudes, dc.measured_sweep.amplitude_units)[
                    0
                ]
                for dc in cmp.directions.values()
            ]
        )
        for ax in (ax_t, ax_f):
            if xs_all.size and np.all(xs_all > 0):
                ax.set_xscale("log")
                ax.set_xlim(xs_all.min() / 1.3, xs_all.max() * 1.3)
            handles, labels = ax.get_legend_handles_labels()
            uniq = dict(zip(labels, handles, strict=True))
            where = "lower right" if ax is ax_t else "best"  # clear of the low bounds
            ax.legend(uniq.values(), uniq.keys(), fontsize=8, loc=where)
        ys = [
            y
            for dc in cmp.directions.values()
            for y in (
                np.where(
                    dc.measured_sweep.at_noise_floor, np.nan, dc.measured_sweep.signal_transmission
                ),
                dc.measured_sweep.transmission_bound,
                dc.predicted_signal,
            )
        ]
        pos = np.concatenate([y[np.isfinite(y) & (y > 0)] for y in ys])
        if pos.size:
            ax_t.set_yscale("log")
            ax_t.set_ylim(pos.min() / 2.0, pos.max() * 2.0)
        else:
            ax_t.text(
                0.5, 0.5, "entry or far cylinder not scanned", ha="center", transform=ax_t.transAxes
            )
        ax_t.set_ylabel("far-end signal energy / E_entry")
        ax_f.set_ylabel("far-cylinder peak (kHz)")
        ax_t.set_title(
            "transmission against amplitude\n(far end in its signal band, noise removed)",
            fontsize=10,
        )
        ax_f.set_title("far-end peak against amplitude (dotted: band edge)")
    return fig


def plot_compare_residuals(cmp: Comparison) -> Figure:
    """Per-cylinder residuals (spectral and time-domain RMS over the compared points)."""
    with style():
        fig, axs = new_figure(1, 1, figsize=(9.0, 3.6))
        ax = axs[0, 0]
        x = cmp.cylinders.astype(float)
        ax.bar(x - 0.2, cmp.spectral_residual, width=0.4, label="spectral", color="tab:blue")
        ax.bar(x + 0.2, cmp.time_residual, width=0.4, label="time domain", color="tab:grey")
        sn = cmp.spectral_noise_per_cylinder()
        if np.any(np.isfinite(sn)):
            ax.plot(x - 0.2, sn, "_", color="navy", ms=8, mew=2, label="spectral: noise alone")
        if np.any(np.isfinite(cmp.noise_residual)):
            ax.plot(x, cmp.noise_residual, "k_", ms=10, mew=2, label="noise floor")
        ax.axhline(1.0, color="k", ls=":", lw=1, label="predicting nothing")
        # points not compared, marked at their cylinder (they were counted, not shown)
        last = int(x.max()) if x.size else 1
        for name, (marker, colour) in BAD_MARK.items():
            hit = sorted(
                {
                    int(c)
                    for dc in cmp.directions.values()
                    for c, col in zip(dc.cylinders, (dc.state == name).T, strict=True)
                    if col.any()
                }
            )
            last = max([last, *hit])
            shown = f"has {SHOWN[name]} points (not compared)"
            mark_missing(ax, hit, colour, marker=marker, label=shown)
        ax.set_xlim(0.5, last + 0.5)
        ax.set_xlabel("cylinder number")
        ax.set_ylabel("relative residual (RMS)")
        fom = cmp.figure_of_merit
        title = "residual per cylinder; figure of merit " + (
            f"{fom:.3f}" if math.isfinite(fom) else "n/a"
        )
        if math.isfinite(cmp.spectral_noise_figure):
            title += f" (noise alone {cmp.spectral_noise_figure:.3f})"
        if cmp.n_noise_floor:
            n = cmp.n_noise_floor
            title += f"\n{n} far record{'' if n == 1 else 's'} at the noise floor not compared"
        ax.set_title(title, fontsize=10)
        ax.legend(fontsize=8)
    return fig
