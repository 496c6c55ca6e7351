"""Spectra of one point of a scan: entry and far cylinder velocity, and the drive."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from analysis.bands import band_edges, entry_cylinder, expected_output_Hz, far_cylinder
from analysis.plots.style import (
    add_gap_background,
    amplitude_label,
    gap_legend_handle,
    new_figure,
    style,
)
from analysis.spectra import amplitude_spectrum, spectrum_db
from analysis.sweep import cylinder_index
from protocols.runfile import ChainInfo, ScanData

__all__ = ["plot_spectra"]


def plot_spectra(
    scan: ScanData, chain: ChainInfo, amplitude_index: int, f_range_Hz: tuple[float, float]
) -> Figure:
    """Velocity spectra (dB re the largest) of the entry and far cylinders, and the drive
    spectrum (dB re its own peak), at one amplitude, over ``f_range_Hz``."""
    n = len(chain.lengths_m)
    onset, cutoff = band_edges(chain)
    rate = scan.sample_rate_Hz
    a = amplitude_index
    with style():
        fig, axs = new_figure(figsize=(7.0, 4.2))
        ax = axs[0, 0]
        curves = []
        for label, number, colour in (
            ("entry", entry_cylinder(scan.direction, n), "tab:green"),
            ("far", far_cylinder(scan.direction, n), "tab:purple"),
        ):
            i = cylinder_index(scan, number)
            if i is None or scan.done[a, i] != 1:
                continue
            spec = amplitude_spectrum(scan.velocity[a, i], rate).band(*f_range_Hz)
            curves.append((f"{label} cylinder #{number}", spec, colour))
        ref = max((float(np.nanmax(s.magnitude)) for _, s, _ in curves), default=1.0)
        for label, spec, colour in curves:
            ax.plot(spec.freq_Hz / 1e3, spectrum_db(spec.magnitude, ref), color=colour, label=label)
        drive_rows = [
            c
            for c in range(len(scan.cylinders))
            if scan.done[a, c] == 1 and np.all(np.isfinite(scan.drive[a, c]))
        ]
        if drive_rows:
            d = amplitude_spectrum(scan.drive[a, drive_rows[0]], rate).band(*f_range_Hz)
            ax.plot(d.freq_Hz / 1e3, spectrum_db(d.magnitude), "k-", lw=1, label="drive (own dB)")
        f_in = scan.f_center_Hz
        ax.axvline(f_in / 1e3, color="k", ls="--", lw=0.8, label=f"input {f_in / 1e3:.2f} kHz")
        f_out = expected_output_Hz(f_in, scan.direction, onset, cutoff)
        ax.axvline(f_out / 1e3, color="tab:red", ls=":", lw=1.2, label="expected output")
        ax.set_xlim(f_range_Hz[0] / 1e3, f_range_Hz[1] / 1e3)
        ax.set_ylim(-60, 3)
        ax.set_xlabel("frequency (kHz)")
        ax.set_ylabel("velocity spectrum (dB re max)")
        amp = amplitude_label(float(scan.amplitudes[a]), scan.amplitude_units)
        ax.set_title(f"{scan.direction.upper()} spectra at amplitude {amp}")
        handles, _ = ax.get_legend_handles_labels()
        if not curves:
            add_gap_background(ax)
            handles.append(gap_legend_handle())
        ax.legend(handles=handles, loc="lower left", framealpha=0.9)
    return fig
