"""The regime in one look: far/near rms transmission against drive amplitude for both
directions, with the linear floor, and the converted far-end peak frequency.

Top: ``sqrt(E_far / E_entry)`` (the far/near rms ratio, dimensionless) per amplitude, log-log;
the dashed line of each direction is its linear floor, the ratio at the smallest amplitude (a
linear chain passes the same fraction at every amplitude, so what rises above the floor is
what the nonlinearity lets through). Where the records show their noise (a pre-trigger), the
ratio is the far end's signal's: its energy in the band where the signal can be, less the
noise's there (:mod:`analysis.noise_floor`). A point whose far end held no more than its
noise is drawn as a downward triangle at the ratio's upper bound; when the smallest amplitude
is one, the floor is the tightest such bound, drawn "at most", and the gains are lower bounds
(unless the first point above the noise passes less: :mod:`analysis.sweep`). Bottom: the far
cylinder's output peak (kHz) per amplitude, with the input frequency (dashed) and the far
cylinder's band edge that the conversion heads for (dotted). The far end always has a largest
line: only the points whose verdict (:func:`analysis.summary.conversion_verdict`, with the gain
over the smallest amplitude) is a conversion are filled; those the run cannot tell
("undetermined": a lower-bound gain) are hollow in their direction's colour; the others (a
linear leak, a line within 2 % of the input) hollow grey, "not converted". Before, a 10 nm RTL
leak at 8.0 kHz (E_far/E_in 7e-8) was drawn as the converted points are.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure

from analysis.plots.quasi_bands import DIRECTION_COLOURS
from analysis.plots.style import (
    MISSING_AT,
    amplitude_scale,
    mark_missing,
    new_figure,
    plot_by_verdict,
    style,
)
from analysis.summary import summary_rows
from analysis.sweep import AmplitudeSweep

__all__ = ["plot_regime", "rms_ratio"]

MARKERS = {"ltr": "o-", "rtl": "s-"}


def rms_ratio(sweep: AmplitudeSweep) -> np.ndarray:
    """Far/near rms ratio ``[A]`` of a sweep: ``sqrt(E_far / E_entry)`` (NaN where unmeasured),
    of the far end's signal where its noise is known (``signal_transmission``: its energy in
    the signal band less the noise's), the quantity the linear floor and the bounds are of."""
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.asarray(sweep.signal_transmission, dtype=np.float64))


def plot_regime(sweeps: Mapping[str, AmplitudeSweep]) -> Figure:
    """The regime figure of one or two directions' amplitude sweeps (see the module doc)."""
    with style():
        fig, axes = new_figure(2, 1, figsize=(6.4, 6.4), sharex=True)
        ax_t, ax_f = axes[0, 0], axes[1, 0]
        units = {sw.amplitude_units for sw in sweeps.values()}
        all_amps = np.concatenate([sw.amplitudes for sw in sweeps.values()])
        factor, unit = amplitude_scale(all_amps, units.pop() if len(units) == 1 else "")
        for d, sw in sweeps.items():
            colour = DIRECTION_COLOURS.get(d, "k")
            amps = sw.amplitudes / factor
            r = rms_ratio(sw)
            # measured: the whole records' ratio (a noise-only far record's signal can be < 0)
            measured = np.isfinite(sw.transmission) & (amps > 0)
            noisy = measured & sw.at_noise_floor
            ok = measured & ~noisy
            missing = f"{d.upper()} failed or not measured"
            at = MISSING_AT.get(d, 0.03)
            mark_missing(ax_t, amps[~measured & (amps > 0)], colour, label=missing, at=at)
            if noisy.any():
                ax_t.plot(amps[noisy], np.sqrt(sw.transmission_bound[noisy]), "v", color=colour,
                          mfc="none", ls="none",
                          label=f"{d.upper()} at the noise floor (at most)")  # fmt: skip
            f_in = float(np.nanmedian(sw.input_Hz))  # drawn whatever was measured
            ax_f.axhline(f_in / 1e3, color=colour, ls="--", lw=1,
                         label=f"{d.upper()} input {f_in / 1e3:.2f} kHz")  # fmt: skip
            if np.isfinite(sw.expected_Hz):  # none without a local-resonance band
                edge = f"{d.upper()} far-cylinder edge {sw.expected_Hz / 1e3:.2f} kHz"
                ax_f.axhline(sw.expected_Hz / 1e3, color=colour, ls=":", lw=1.5, label=edge)
            gone = ~sw.far_measured & (amps > 0)  # measured without a peak is not missing
            mark_missing(ax_f, amps[gone], colour, label=missing, at=at)
            if not ok.any():
                continue
            floor = float(np.sqrt(sw.reference)) if np.isfinite(sw.reference) else math.nan
            top = float(np.nanmax(r[ok]))
            bound = sw.reference_is_bound
            over = f" (x{'>=' if bound else ''}{top / floor:.3g} over the floor)"
            label = d.upper() + (over if math.isfinite(floor) else "")
            ax_t.plot(amps[ok], r[ok], MARKERS.get(d, "o-"), color=colour, label=label)
            if math.isfinite(floor):
                ax_t.axhline(floor, color=colour, ls="--", lw=1,
                             label=f"{d.upper()} linear floor {'at most ' if bound else ''}"
                             f"{floor:.2g}")  # fmt: skip
            fo = np.isfinite(sw.output_Hz) & (amps > 0)
            verdicts = np.array([r["conversion"] for r in summary_rows(sw)], dtype=object)
            # the run cannot tell ("undetermined": a lower-bound gain) is neither converted nor
            # not (a reviewer: it was drawn "not converted"); the styles: plots.style
            marker = MARKERS.get(d, "o-")[0]
            ax_f.plot(amps[fo], sw.output_Hz[fo] / 1e3, "-", color=colour, lw=1, alpha=0.5)
            peak = f"{d.upper()} far-end peak"
            labels = {
                "converted": f"{peak}, converted",
                "undetermined": f"{peak}, undetermined",
                "not converted": f"{d.upper()} largest far-end line, not converted",
            }
            y = sw.output_Hz[fo] / 1e3
            plot_by_verdict(ax_f, amps[fo], y, verdicts[fo], marker, colour, labels)
        ax_t.set_xscale("log")
        ax_t.set_yscale("log")
        ax_t.set_ylabel("far/near rms ratio")
        ax_t.set_title("Transmission against drive amplitude")
        lo, hi = ax_t.get_ylim()  # room below the data for the legend (the bounds sit top
        if 0 < lo < hi:  # left, the rising curves top right, the floors at the bottom)
            ax_t.set_ylim(lo / (hi / lo) ** 0.3, hi)
        ax_t.legend(fontsize="x-small", ncol=2, loc="lower right")
        ax_t.grid(True, which="both", alpha=0.3)
        ax_f.set_xlabel(f"drive amplitude ({unit})")
        ax_f.set_ylabel("far-end output peak (kHz)")
        # two columns low on the left: one column covered the small amplitudes' lines
        lo, hi = ax_f.get_ylim()
        ax_f.set_ylim(lo - 0.35 * (hi - lo), hi)
        ax_f.legend(fontsize="x-small", ncol=2, loc="lower left")
        ax_f.grid(True, alpha=0.3)
    return fig
