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

Noise (:mod:`analysis.noise_floor`). Where the far record holds, within the band where the
signal can be (:func:`analysis.bands.signal_band_Hz`), no more than the noise its pre-trigger
samples show there (``at_noise_floor``), its transmission is only bounded from above
(``transmission_bound``, 4 x the noise's energy in that band over E_entry: a bound on the far
end's signal within the band; the transmission itself stays the whole records' E_far/E_entry),
its spectral peak is a noise line and is not given (``output_Hz`` and ``detuning_Hz`` NaN), and
it has no gain. When the smallest amplitude is at the noise floor, the linear reference is the
tightest such bound below the first amplitude that stands above the noise
(``reference_is_bound``), and every gain is then a lower bound, unless the first amplitude
above the noise passes no more than that bound: then it is the reference.
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
    signal_band_Hz,
)
from analysis.noise_floor import (
    MIN_BAND_DOF,
    RESOLVED_FACTOR,
    band_dof,
    band_energy,
    band_noise_energy,
    resolved,
)
from analysis.spectra import amplitude_spectrum, peak_frequency
from analysis.transmission import energy_transmission, signal_energy
from protocols.runfile import ChainInfo, ScanData

__all__ = [
    "AmplitudeSweep",
    "amplitude_sweep",
    "cylinder_index",
    "input_frequency_Hz",
    "linear_reference",
    "output_peak_definition",
    "transmission_gain",
]


@dataclass(frozen=True)
class AmplitudeSweep:
    """One direction's sweep. Shapes: ``amplitudes [A]``, ``freq_Hz [F]``, ``magnitude [A, F]``
    (far-cylinder velocity spectrum, m; NaN rows where not measured), ``input_Hz [A]``,
    ``output_Hz [A]``, ``detuning_Hz [A]``, ``transmission [A]`` (E_far / E_entry),
    ``transmission_gain [A]`` (transmission over the linear reference), ``far_noise_ratio
    [A]`` (the far record's energy over the noise's, NaN without pre-trigger samples),
    ``at_noise_floor [A]`` (measured, and not above the noise), ``transmission_bound [A]`` (an
    upper bound of the transmission where at the noise floor, NaN elsewhere; it bounds the far
    end's energy within ``signal_band_Hz``, over E_entry);
    ``signal_transmission [A]``: the far end's signal over E_entry, its energy in
    ``signal_band_Hz`` less the noise's there (the whole records' ratio where the noise is not
    known or zero: a model run), which the gains and the linear reference use;
    ``signal_band_Hz``: the band where the signal can be, over which the far record's energy
    is set against its noise's (:func:`analysis.bands.signal_band_Hz`);
    ``reference``: the linear reference (E_far / E_entry, NaN without one);
    ``reference_is_bound``: it is such a bound, so the gains are lower bounds;
    ``far_measured [A]``: the far record was measured (whether or not a peak was found);
    ``noise_known``: a measured far record had pre-trigger samples to estimate its noise;
    ``noise_over_whole_record``: its pre-trigger was too short to know the noise within the
    signal band (:data:`analysis.noise_floor.MIN_BAND_DOF`), so ``signal_band_Hz`` is the whole
    record, 0..Nyquist."""

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
    signal_band_Hz: tuple[float, float]
    signal_transmission: NDArray[np.float64]
    far_noise_ratio: NDArray[np.float64]
    at_noise_floor: NDArray[np.bool_]
    transmission_bound: NDArray[np.float64]
    reference: float
    reference_is_bound: bool
    far_measured: NDArray[np.bool_]
    noise_known: bool
    noise_over_whole_record: bool = False


def cylinder_index(scan: ScanData, number: int) -> int | None:
    """0-based index of cylinder ``number`` (1-based) in ``scan.cylinders``; None if not scanned."""
    hits = np.nonzero(scan.cylinders == number)[0]
    return int(hits[0]) if hits.size else None


def input_frequency_Hz(scan: ScanData) -> NDArray[np.float64]:
    """Input frequency per amplitude ``[A]`` (Hz): the median peak of the drive spectra of the
    measured points at that amplitude (one record at a small drive is noisy: 8.887 kHz for an
    8.92 kHz carrier), else the burst's centre frequency."""
    rate = scan.sample_rate_Hz
    f_c = scan.f_center_Hz
    out = np.full(len(scan.amplitudes), f_c, dtype=np.float64)
    for a in range(len(scan.amplitudes)):
        d = scan.drive[a]  # [C, S]
        usable = (scan.done[a] == 1) & np.all(np.isfinite(d), axis=-1) & np.any(d != 0, axis=-1)
        if not usable.any():
            continue
        peaks = peak_frequency(amplitude_spectrum(d[usable], rate), 0.3 * f_c, 3.0 * f_c)
        if np.any(np.isfinite(peaks)):
            out[a] = float(np.nanmedian(peaks))
    return out


def burst_sigma_f_Hz(scan: ScanData) -> float | None:
    """The burst's spectral Gaussian sigma (Hz), ``1 / (2 pi sigma_t)`` with ``sigma_t`` the
    stored width or ``cycles / (6 f_c)`` (:mod:`instruments.burst`); None when neither is
    stored."""
    if scan.width_s is not None and math.isfinite(scan.width_s) and scan.width_s > 0:
        return 1.0 / (2.0 * math.pi * scan.width_s)
    if scan.cycles is not None and math.isfinite(scan.cycles) and scan.cycles > 0:
        return 1.0 / (2.0 * math.pi * scan.cycles / (6.0 * scan.f_center_Hz))
    return None


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
    in_hz = input_frequency_Hz(scan)
    transmission = energy_transmission(v_entry, v_far, rate)
    # the noise floor is decided within the band where the signal can be: over the whole
    # record, broadband digitiser noise hid a narrowband far-end line 10x above its own band's
    sig_band = signal_band_Hz(
        scan.f_center_Hz, scan.direction, onset, cutoff, burst_sigma_f_Hz(scan)
    )
    level_band = f_range
    whole = band_dof(scan.time_s, rate, level_band) < MIN_BAND_DOF
    if whole:  # a short pre-trigger: the whole record decides, as before
        sig_band = level_band = (0.0, rate / 2.0)
    # for the noise floor and its bound, the far record's mean removed as the pre-trigger's
    # is (band_noise_energy): over the whole record an offset had read as signal (pure noise
    # with a 5 sigma offset stood "resolved" in every record; a reviewer)
    with np.errstate(invalid="ignore"):
        v_far_ac = v_far - np.mean(v_far, axis=-1, keepdims=True)
    e_far = band_energy(v_far_ac, rate, sig_band)
    e_entry = signal_energy(v_entry, rate)
    far_measured = np.all(np.isfinite(v_far), axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        noise = band_noise_energy(v_far, scan.time_s, rate, sig_band, level_band)
        noise_ratio = np.where(noise > 0, e_far / noise, np.where(noise == 0, np.inf, np.nan))
        # the far record alone decides (its entry point may have failed)
        floor = far_measured & ~resolved(e_far, noise)
        bound = np.where(floor & (e_entry > 0), RESOLVED_FACTOR * noise / e_entry, np.nan)
    # a noise line is no output peak, nor a maximum on the search range's edge
    out_hz = np.where(floor, np.nan, peak_frequency(spec, interior=True))
    # the gain sets like against like: where the noise is known and not zero, the far end's
    # signal (its energy in the signal band less the noise's there) over E_entry, the quantity
    # the bounds bound; the whole records' ratio of a noise-dominated record is mostly noise
    with np.errstate(divide="ignore", invalid="ignore"):
        signal_t = np.where(
            np.isfinite(noise) & (noise > 0), (e_far - noise) / e_entry, transmission
        )
    signal_t = np.where(np.isfinite(transmission), signal_t, np.nan)
    reference, is_bound = linear_reference(scan.amplitudes, signal_t, floor, bound)
    gain = np.where(np.isfinite(signal_t) & ~floor, signal_t / reference, np.nan)
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
        transmission_gain=gain,
        expected_Hz=expected_output_Hz(scan.f_center_Hz, scan.direction, onset, cutoff),
        f_range_Hz=f_range,
        signal_band_Hz=sig_band,
        signal_transmission=signal_t,
        far_noise_ratio=noise_ratio,
        at_noise_floor=floor,
        transmission_bound=bound,
        reference=reference,
        reference_is_bound=is_bound,
        far_measured=far_measured,
        noise_known=bool(np.any(np.isfinite(noise[far_measured]))),
        noise_over_whole_record=whole,
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


def linear_reference(
    amplitudes: NDArray[np.float64],
    transmission: NDArray[np.float64],
    at_noise_floor: NDArray[np.bool_],
    bound: NDArray[np.float64],
) -> tuple[float, bool]:
    """The linear reference of a sweep's gains and whether it is only an upper bound.

    The transmission at the smallest measured amplitude (finite and > 0) when its far record
    stands above the noise; when it does not, the smallest upper ``bound`` of the points at the
    noise floor below the first amplitude that stands above it (a linear chain passes the same
    fraction at every amplitude, so each such bound bounds the linear fraction), unless that
    first resolved point's transmission is no larger than the bound: it is then within what the
    linear regime allows and is the reference itself (not a bound). NaN when fewer than two
    amplitudes were measured."""
    amps = np.abs(np.asarray(amplitudes, dtype=np.float64))
    t = np.asarray(transmission, dtype=np.float64)
    # a point at the noise floor counts by its bound (its signal, noise removed, can be < 0)
    ok = np.isfinite(t) & ((t > 0) | np.asarray(at_noise_floor, dtype=bool))
    if np.count_nonzero(ok) < 2:
        return math.nan, False
    first = int(np.flatnonzero(ok)[np.argmin(amps[ok])])
    if not at_noise_floor[first]:
        return float(t[first]), False
    above = ok & ~at_noise_floor
    first_above = float(np.min(amps[above])) if above.any() else math.inf
    below = ok & at_noise_floor & (amps < first_above) & np.isfinite(bound)
    tightest = float(np.min(bound[below])) if below.any() else math.inf
    if above.any():
        t_first = float(t[above][np.argmin(amps[above])])
        if t_first <= tightest:  # the first resolved point is within the bounds: linear
            return t_first, False
    return tightest if math.isfinite(tightest) else math.nan, math.isfinite(tightest)


def transmission_gain(
    amplitudes: NDArray[np.float64], transmission: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``transmission [A]`` over the transmission at the smallest amplitude where it is finite
    and > 0 (the linear reference, with no noise estimate: :func:`linear_reference`); all NaN
    when fewer than two amplitudes are finite."""
    t = np.asarray(transmission, dtype=np.float64)
    ref, _ = linear_reference(amplitudes, t, np.zeros(t.shape, bool), np.full(t.shape, np.nan))
    return np.where(np.isfinite(t), t / ref, np.nan)
