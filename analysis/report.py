"""Every figure a run file supports, and its summary, written to a folder.

What is drawn (names without extension; each written as PNG and PDF):

- ``quasi_bands``: the chain's quasi-band diagram with the scanned inputs (always);
- ``regime``: far/near rms ratio against amplitude for both directions with the linear floor,
  and the far-end output peak against amplitude (any sweep of >= 2 amplitudes).
- ``amplitude_sweep``: far-cylinder spectrum against amplitude, both directions, and the
  detuning (for the directions whose far cylinder was measured at two amplitudes or more; a
  single amplitude is no sweep, and the summary says why the figure was left out);
- per direction ``<dir>`` with measured points, at the highest amplitude measured:
  ``spectra_<dir>``, ``spatial_frequency_<dir>``, ``stft_<dir>``; and ``spatiotemporal_<dir>``
  at the lowest and the highest amplitude measured;
- ``summary.json`` (and the text returned for printing).

The summary is computed before anything is drawn (drawing takes most of the time: 5 of 5.4 s
on a ``biafc_sweep`` run): ``on_summary`` gets its text at once, and ``on_written`` each figure
as its files are saved, so ``biafc figures`` speaks within about a second, not at the end.

Points not measured (partial files) stay NaN and show as the grey hatched background.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from analysis.bands import band_edges, far_cylinder, linear_limit_cylinder
from analysis.spatial import spatial_frequency_map
from analysis.spatiotemporal import SpatiotemporalMap, spatiotemporal_map
from analysis.spectra import amplitude_spectrum
from analysis.stft import Stft, stft
from analysis.summary import format_summary, summarize, write_summary
from analysis.sweep import AmplitudeSweep, amplitude_sweep
from protocols.runfile import RunData, ScanData

if TYPE_CHECKING:  # matplotlib is imported once the summary is out (0.3 s)
    from matplotlib.figure import Figure

#: amplitudes with the far cylinder measured that an amplitude-sweep figure needs
MIN_SWEEP_AMPLITUDES = 2

__all__ = [
    "MIN_SWEEP_AMPLITUDES",
    "FigureReport",
    "measured_amplitudes",
    "stft_cylinders",
    "write_figures",
]


@dataclass
class FigureReport:
    """What :func:`write_figures` wrote: ``figures`` (name -> paths), the summary dict and its
    text, and ``skipped`` (name -> reason) for figures the file does not support."""

    figures: dict[str, list[Path]] = field(default_factory=dict)
    summary: dict[str, Any] = field(default_factory=dict)
    summary_text: str = ""
    summary_path: Path | None = None
    skipped: dict[str, str] = field(default_factory=dict)


def measured_amplitudes(scan: ScanData) -> list[int]:
    """Indices of the amplitudes with at least one measured cylinder, in order."""
    return [a for a in range(len(scan.amplitudes)) if np.any(scan.done[a] == 1)]


def stft_cylinders(direction: str, n_cylinders: int, count: int = 6) -> list[int]:
    """``count`` cylinder numbers (1-based) evenly spaced from the entry to the far end."""
    nums = np.unique(np.round(np.linspace(1, n_cylinders, count)).astype(int)).tolist()
    return nums if direction == "ltr" else nums[::-1]


def write_figures(
    run: RunData,
    out_dir: str | Path,
    *,
    on_summary: Callable[[str], None] | None = None,
    on_written: Callable[[str, list[Path]], None] | None = None,
) -> FigureReport:
    """Write every figure ``run`` supports and ``summary.json`` into ``out_dir``.

    ``on_summary(text)`` is called with the summary's text before any figure is drawn; the
    figures left out are known only once drawn, so that text has no "left out" lines (the
    report's ``summary_text`` and ``summary.json`` have them). ``on_written(name, paths)`` is
    called as each figure's files are saved."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = FigureReport()
    # each direction's sweep once, for the summary and the figures (each computed its own)
    all_sweeps = {d: amplitude_sweep(scan, run.chain) for d, scan in run.scans.items()}
    report.summary = summarize(run, all_sweeps)
    if on_summary is not None:
        on_summary(format_summary(report.summary))

    from analysis.plots.quasi_bands import plot_quasi_bands
    from analysis.plots.regime_plot import plot_regime
    from analysis.plots.spatial_plot import plot_spatial_frequency
    from analysis.plots.spatiotemporal_plot import plot_spatiotemporal
    from analysis.plots.spectra_plot import plot_spectra
    from analysis.plots.stft_plot import plot_stft
    from analysis.plots.style import amplitude_label, save_figure
    from analysis.plots.sweep_plot import plot_amplitude_sweep

    def _save(fig: Figure, name: str) -> None:
        report.figures[name] = save_figure(fig, out, name)
        if on_written is not None:
            on_written(name, report.figures[name])

    chain = run.chain
    n = len(chain.lengths_m)
    onset, cutoff = band_edges(chain)

    inputs = [(d, s.f_center_Hz) for d, s in run.scans.items()]
    _save(plot_quasi_bands(chain, inputs), "quasi_bands")

    sweeps: dict[str, AmplitudeSweep] = {}
    sweep_why: dict[str, str] = {}
    for direction, scan in run.scans.items():
        amps = measured_amplitudes(scan)
        if not amps:
            report.skipped[f"*_{direction}"] = "no point measured"
            continue
        sw = all_sweeps[direction]
        # measured, with or without a peak to give (at the noise floor, or none inside the range)
        n_far = int(np.count_nonzero(sw.far_measured))
        if n_far >= MIN_SWEEP_AMPLITUDES:
            sweeps[direction] = sw
        else:
            sweep_why[direction] = (
                f"{direction}: far cylinder {sw.far} measured at {n_far} amplitude(s); a sweep "
                f"needs {MIN_SWEEP_AMPLITUDES}"
            )
        f_range = sw.f_range_Hz
        rate = scan.sample_rate_Hz
        hi, lo = amps[-1], amps[0]
        amp_label = amplitude_label(float(scan.amplitudes[hi]), scan.amplitude_units)

        _save(plot_spectra(scan, chain, hi, f_range), f"spectra_{direction}")

        smap = spatial_frequency_map(scan.velocity[hi], scan.cylinders, rate, f_range)
        drive_rows = [
            c
            for c in range(len(scan.cylinders))
            if scan.done[hi, c] == 1 and np.all(np.isfinite(scan.drive[hi, c]))
        ]
        drive = amplitude_spectrum(scan.drive[hi, drive_rows[0]], rate) if drive_rows else None
        fig = plot_spatial_frequency(
            smap,
            direction,
            scan.f_center_Hz,
            onset,
            cutoff,
            far_cylinder(direction, n),
            drive,
            title=f"{direction.upper()} spatial-frequency map, amplitude {amp_label}",
        )
        _save(fig, f"spatial_frequency_{direction}")

        panels: list[tuple[int, Stft]] = []
        edges: list[tuple[float, float]] = []
        for number in stft_cylinders(direction, n):
            hits = np.nonzero(scan.cylinders == number)[0]
            if not hits.size:
                continue
            rec = scan.velocity[hi, hits[0]].astype(np.float64)
            try:
                panels.append((number, stft(rec, rate, t0_s=float(scan.time_s[0]))))
            except ValueError as exc:  # a record shorter than one STFT frame
                report.skipped[f"stft_{direction}"] = str(exc)
                break
            edges.append((float(onset[number - 1]), float(cutoff[number - 1])))
        if panels and f"stft_{direction}" not in report.skipped:
            fig = plot_stft(
                panels, f_range, f"{direction.upper()} STFT, amplitude {amp_label}", edges
            )
            _save(fig, f"stft_{direction}")

        st_panels: list[tuple[str, SpatiotemporalMap]] = []
        for a in dict.fromkeys([lo, hi]):
            label = f"{direction.upper()} " + amplitude_label(
                float(scan.amplitudes[a]), scan.amplitude_units
            )
            st_panels.append(
                (label, spatiotemporal_map(scan.velocity[a], scan.cylinders, scan.time_s))
            )
        limit = linear_limit_cylinder(scan.f_center_Hz, direction, onset, cutoff)
        fig = plot_spatiotemporal(st_panels, limit, n_cylinders=len(onset))
        _save(fig, f"spatiotemporal_{direction}")

    if sweeps:
        _save(plot_amplitude_sweep(sweeps), "amplitude_sweep")
        if any(np.isfinite(sw.transmission).any() for sw in sweeps.values()):
            _save(plot_regime(sweeps), "regime")
        else:  # its log axes had nothing to draw ("Data cannot be log-scaled")
            report.skipped["regime"] = (
                "no far/near ratio: the entry cylinder was not measured at any amplitude"
            )
        for direction, why in sweep_why.items():
            report.skipped[f"amplitude_sweep ({direction})"] = why
            report.skipped[f"regime ({direction})"] = why
    else:
        why_all = "; ".join(sweep_why.values()) or "no scan measured"
        report.skipped["amplitude_sweep"] = why_all
        report.skipped["regime"] = why_all

    report.summary["figures_left_out"] = dict(report.skipped)
    report.summary_text = format_summary(report.summary)
    report.summary_path = write_summary(report.summary, out / "summary.json")
    return report
