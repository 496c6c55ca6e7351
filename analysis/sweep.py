"""Amplitude sweep (paper Fig. 2d-e): the far cylinder's spectrum as the drive amplitude rises.

For one direction of a run: the far cylinder (#N for LTR, #1 for RTL) velocity spectrum at
every amplitude, the input frequency (peak of the drive spectrum, or the burst's centre
frequency when no drive was recorded), the output peak (far cylinder, in the search range of
:func:`analysis.bands.peak_search_range_Hz`), the detuning ``output - input`` (Hz), the energy
transmission from the entry cylinder to the far one, its gain over the linear regime, and the
band edge where the output is expected to saturate (:func:`analysis.bands.expected_output_Hz`).

The transmission gain is ``transmission / transmission at the smallest measured amplitude``.
A linear chain passes the same fraction at every amplitude (gain 1), however broad the burst
and however much of its tail leaks through where the end cylinders' bands nearly meet; the
gain grows only when the contacts act nonlinearly. It therefore needs the smallest amplitude of
the sweep to be in the linear regime (dynamic overlap well below the static one, about 1 um
for the default chain), and is NaN when fewer than two amplitudes were measured.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from analysis.bands import (
    band_edges,
    entry_cylinder,
    expected_output_Hz,
    far_cylinder,
    peak_search_range_Hz,
)
from analysis.spectra import amplitude_spectrum, peak_frequency
from analysis.transmission import energy_transmission
from protocols.runfile import ChainInfo, ScanData

__all__ = [
    "AmplitudeSweep",
    "amplitude_sweep",
    "cylinder_index",
    "input_frequency_Hz",
    "output_peak_definition",
    "transmission_gain",
]


@dataclass(frozen=True)
class AmplitudeSweep:
    """One direction's sweep. Shapes: ``amplitudes [A]``, ``freq_Hz [F]``, ``magnitude [A, F]``
    (far-cylinder velocity spectrum, m; NaN rows where not measured), ``input_Hz [A]``,
    ``output_Hz [A]``, ``detuning_Hz [A]``, ``transmission [A]`` (E_far / E_entry),
    ``transmission_gain [A]`` (transmission over that of the smallest measured amplitude)."""

    direction: str
    amplitudes: NDArray[np.float64]
    amplitude_units: str
    entry: int
    far: int
    freq_Hz: NDArray[np.float64]
    magnitude: NDArray[np.float64]
    input_Hz: NDArray[np.float64]
    output_Hz: NDArray[np.float64]
    detuning_Hz: NDArray[np.float64]
    transmission: NDArray[np.float64]
    transmission_gain: NDArray[np.float64]
    expected_Hz: float
    f_range_Hz: tuple[float, float]


def cylinder_index(scan: ScanData, number: int) -> int | None:
    """0-based index of cylinder ``number`` (1-based) in ``scan.cylinders``; None if not scanned."""
    hits = np.nonzero(scan.cylinders == number)[0]
    return int(hits[0]) if hits.size else None


def input_frequency_Hz(scan: ScanData) -> NDArray[np.float64]:
    """Input frequency per amplitude ``[A]`` (Hz): the peak of the drive spectrum of the first
    measured point at that amplitude, else the burst's centre frequency."""
    rate = scan.sample_rate_Hz
    f_c = scan.f_center_Hz
    out = np.full(len(scan.amplitudes), f_c, dtype=np.float64)
    for a in range(len(scan.amplitudes)):
        for c in range(len(scan.cylinders)):
            d = scan.drive[a, c]
            if scan.done[a, c] == 1 and np.all(np.isfinite(d)) and np.any(d != 0):
                spec = amplitude_spectrum(d, rate)
                f = float(peak_frequency(spec, 0.3 * f_c, 3.0 * f_c))
                if math.isfinite(f):
                    out[a] = f
                break
    return out


def amplitude_sweep(scan: ScanData, chain: ChainInfo) -> AmplitudeSweep:
    """The amplitude sweep of one direction (see the module docstring)."""
    n = len(chain.lengths_m)
    try:
        onset, cutoff = band_edges(chain)
    except ValueError:  # no local-resonance band (preload 0 N): the peak searched near f_in
        onset = cutoff = np.full(n, np.nan)
    entry = entry_cylinder(scan.direction, n)
    far = far_cylinder(scan.direction, n)
    rate = scan.sample_rate_Hz
    f_range = peak_search_range_Hz(scan.f_center_Hz, onset, cutoff)
    n_amp = len(scan.amplitudes)
    i_far = cylinder_index(scan, far)
    i_entry = cylinder_index(scan, entry)
    s_len = len(scan.time_s)
    nan_rec = np.full((n_amp, s_len), np.nan)
    v_far = scan.velocity[:, i_far, :].astype(np.float64) if i_far is not None else nan_rec
    v_entry = scan.velocity[:, i_entry, :].astype(np.float64) if i_entry is not None else nan_rec
    spec = amplitude_spectrum(v_far, rate).band(*f_range)
    out_hz = peak_frequency(spec)
    in_hz = input_frequency_Hz(scan)
    transmission = energy_transmission(v_entry, v_far, rate)
    return AmplitudeSweep(
        direction=scan.direction,
        amplitudes=np.asarray(scan.amplitudes, dtype=np.float64),
        amplitude_units=scan.amplitude_units,
        entry=entry,
        far=far,
        freq_Hz=spec.freq_Hz,
        magnitude=spec.magnitude,
        input_Hz=in_hz,
        output_Hz=out_hz,
        detuning_Hz=out_hz - in_hz,
        transmission=transmission,
        transmission_gain=transmission_gain(scan.amplitudes, transmission),
        expected_Hz=expected_output_Hz(scan.f_center_Hz, scan.direction, onset, cutoff),
        f_range_Hz=f_range,
    )


def output_peak_definition(sweep: AmplitudeSweep) -> str:
    """What ``output_Hz`` (``f_out``) is, in words: the one definition of the far-end peak that
    every command prints (``biafc simulate``, ``biafc figures``)."""
    lo, hi = sweep.f_range_Hz
    where = (
        "the bands' neighbourhood without the contacts' low-frequency drift and the harmonics"
        if math.isfinite(sweep.expected_Hz)
        else "half to one and a half times the input: the chain has no local-resonance band"
    )
    return (
        f"far-end output peak f_out (largest line of cylinder {sweep.far}'s velocity spectrum "
        f"in {lo / 1e3:.2f}-{hi / 1e3:.2f} kHz, {where})"
    )


def transmission_gain(
    amplitudes: NDArray[np.float64], transmission: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``transmission [A]`` over the transmission at the smallest amplitude where it is finite
    and > 0 (the linear reference); all NaN when fewer than two amplitudes are finite."""
    amps = np.abs(np.asarray(amplitudes, dtype=np.float64))
    t = np.asarray(transmission, dtype=np.float64)
    ok = np.isfinite(t) & (t > 0)
    if np.count_nonzero(ok) < 2:
        return np.full(t.shape, np.nan)
    ref = t[ok][np.argmin(amps[ok])]
    return np.where(np.isfinite(t), t / ref, np.nan)
