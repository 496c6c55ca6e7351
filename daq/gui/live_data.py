"""What the live views show, as plain arrays (no Qt): filled from engine events or a run file.

One :class:`ScanView` per direction holds, for the plan's amplitudes ``[A]`` and cylinders
``[C]``: the velocity spectra ``spectrum [A, C, F]`` (m, NaN until measured, restricted to
``0 .. F_MAX_FACTOR * f_center``) and the magnitude at the input frequency ``at_input [A, C]``
(m), from which the spatial-frequency map and the amplitude-sweep map are drawn.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from analysis.spectra import amplitude_spectrum, n_fft_for
from instruments.burst import Burst, burst_waveform
from protocols.runfile import ChainInfo, PointState, RunData

__all__ = ["F_MAX_FACTOR", "LiveData", "ScanView", "Trace"]

#: spectra are kept up to this multiple of the burst's centre frequency
F_MAX_FACTOR = 2.5


@dataclass
class Trace:
    """The last measured record: ``time_s [S]``, ``velocity_m_per_s [S]``, ``drive [S]`` in
    ``drive_units`` (the recorded drive, e.g. V; ``"norm."``: the protocol's burst, peak 1,
    when no drive was recorded), where it was measured, and its spectrum ``freq_Hz [F]``,
    ``magnitude [F]`` (m)."""

    direction: str
    amplitude: float
    amplitude_units: str
    cylinder: int
    time_s: NDArray[np.float64]
    velocity_m_per_s: NDArray[np.float64]
    drive: NDArray[np.float64]
    freq_Hz: NDArray[np.float64]
    magnitude: NDArray[np.float64]
    drive_units: str = "norm."


@dataclass
class ScanView:
    """One direction's maps. Shapes: ``amplitudes [A]``, ``cylinders [C]``, ``freq_Hz [F]``,
    ``spectrum [A, C, F]`` (m), ``at_input [A, C]`` (m)."""

    direction: str
    f_center_Hz: float
    amplitudes: NDArray[np.float64]
    amplitude_units: str
    cylinders: NDArray[np.int32]
    freq_Hz: NDArray[np.float64]
    spectrum: NDArray[np.float64]
    at_input: NDArray[np.float64]
    n_filled: int = 0
    #: ``[A, C]``: points that failed (every retry), drawn as such, not as "not measured yet"
    failed: NDArray[np.bool_] = field(default_factory=lambda: np.zeros((0, 0), dtype=bool))

    def __post_init__(self) -> None:
        if self.failed.shape != self.at_input.shape:
            self.failed = np.zeros(self.at_input.shape, dtype=bool)

    @classmethod
    def empty(
        cls,
        direction: str,
        f_center_Hz: float,
        amplitudes: NDArray[np.float64],
        amplitude_units: str,
        cylinders: NDArray[np.int32],
        n_samples: int,
        sample_rate_Hz: float,
    ) -> ScanView:
        n_fft = n_fft_for(n_samples)
        freq = np.asarray(np.fft.rfftfreq(n_fft, 1.0 / sample_rate_Hz), np.float64)
        freq = freq[freq <= F_MAX_FACTOR * f_center_Hz]
        a, c = len(amplitudes), len(cylinders)
        return cls(
            direction,
            f_center_Hz,
            np.asarray(amplitudes, np.float64),
            amplitude_units,
            np.asarray(cylinders, np.int32),
            freq,
            np.full((a, c, freq.size), np.nan),
            np.full((a, c), np.nan),
        )

    def put(self, ai: int, ci: int, magnitude: NDArray[np.float64]) -> None:
        """Store one point's spectrum ``magnitude [F]`` (already cut to ``freq_Hz``)."""
        self.spectrum[ai, ci] = magnitude[: self.freq_Hz.size]
        k = int(np.argmin(np.abs(self.freq_Hz - self.f_center_Hz)))
        self.at_input[ai, ci] = magnitude[k]
        self.failed[ai, ci] = False  # a resumed run measured it after all
        self.n_filled += 1

    def mark_failed(self, ai: int, ci: int) -> None:
        """Point (``ai``, ``ci``) failed: it keeps no spectrum, and is marked."""
        self.failed[ai, ci] = True


@dataclass
class LiveData:
    """The views' data: the chain, one :class:`ScanView` per direction, and the last trace."""

    chain: ChainInfo | None = None
    scans: dict[str, ScanView] = field(default_factory=dict)
    bursts: dict[str, Burst] = field(default_factory=dict)
    last: Trace | None = None
    n_points: int = 0

    @classmethod
    def for_plan(cls, plan: Any, protocol: Any, chain: ChainInfo | None) -> LiveData:
        """Empty maps for a :class:`daq.engine.Plan` of a validated ``Protocol``."""
        acq = protocol.acquisition
        n_s = acq.n_samples()
        out = cls(chain=chain)
        for d in plan.directions:
            burst = protocol.burst[d].burst()
            out.bursts[d] = burst
            out.scans[d] = ScanView.empty(
                d,
                burst.f_center_Hz,
                plan.amplitudes,
                plan.amplitude_units,
                plan.cylinders,
                n_s,
                acq.rate,
            )
        return out

    def add_point(self, data: dict[str, Any]) -> Trace:
        """Take a ``point_done`` event's data; returns the new last trace."""
        d = str(data["direction"])
        t = np.asarray(data["time_s"], np.float64)
        v = np.asarray(data["velocity_m_per_s"], np.float64)
        rate = float(1.0 / np.median(np.diff(t)))
        spec = amplitude_spectrum(v, rate)
        scan = self.scans.get(d)
        if scan is not None:
            spec = spec.band(0.0, float(scan.freq_Hz[-1]) if scan.freq_Hz.size else 0.0)
            mag = spec.magnitude
            if spec.freq_Hz.shape != scan.freq_Hz.shape or not np.allclose(
                spec.freq_Hz, scan.freq_Hz
            ):  # the digitiser's actual rate differs from the requested one
                mag = np.interp(scan.freq_Hz, spec.freq_Hz, mag)
            scan.put(int(data["amplitude_index"]), int(data["cylinder_index"]), mag)
        burst = self.bursts.get(d)
        if "drive" in data:
            drive = np.asarray(data["drive"], np.float64)
            drive_units = str(data.get("drive_units", "V"))
        else:
            drive = burst_waveform(t, burst) if burst is not None else np.zeros_like(t)
            drive_units = "norm."
        self.last = Trace(
            d,
            float(data["amplitude"]),
            str(data.get("amplitude_units", "")),
            int(data["cylinder"]),
            t,
            v,
            drive,
            spec.freq_Hz,
            spec.magnitude,
            drive_units,
        )
        self.n_points += 1
        return self.last

    @property
    def n_failed(self) -> int:
        """Points failed now (a resumed run that measures one takes it off)."""
        return sum(int(np.count_nonzero(scan.failed)) for scan in self.scans.values())

    def add_failed(self, data: dict[str, Any]) -> None:
        """Take a ``point_failed`` event's data: the point is marked failed in its maps."""
        scan = self.scans.get(str(data["direction"]))
        if scan is not None:
            scan.mark_failed(int(data["amplitude_index"]), int(data["cylinder_index"]))

    @classmethod
    def from_run(cls, run: RunData) -> LiveData:
        """Every measured point of a run file (for browsing a finished or interrupted run)."""
        out = cls(chain=run.chain)
        for d, s in run.scans.items():
            rate = s.sample_rate_Hz
            if s.cycles is not None:
                burst = Burst(s.f_center_Hz, cycles=s.cycles)
            else:
                burst = Burst(s.f_center_Hz, cycles=None, width_s=s.width_s)
            out.bursts[d] = burst
            view = ScanView.empty(
                d, s.f_center_Hz, s.amplitudes, s.amplitude_units, s.cylinders, s.time_s.size, rate
            )
            out.scans[d] = view
            view.failed = np.asarray(s.done == PointState.FAILED)
            done = s.is_done()
            for ai, ci in zip(*np.nonzero(done), strict=True):
                v = np.asarray(s.velocity[ai, ci], np.float64)
                spec = amplitude_spectrum(v, rate).band(0.0, float(view.freq_Hz[-1]))
                view.put(int(ai), int(ci), spec.magnitude)
                drive, drive_units = _drive_of(s, int(ai), int(ci), burst)
                out.last = Trace(
                    d,
                    float(s.amplitudes[ai]),
                    s.amplitude_units,
                    int(s.cylinders[ci]),
                    np.asarray(s.time_s, np.float64),
                    v,
                    drive,
                    spec.freq_Hz,
                    spec.magnitude,
                    drive_units,
                )
                out.n_points += 1
        return out


def _drive_of(scan: Any, ai: int, ci: int, burst: Burst) -> tuple[NDArray[np.float64], str]:
    """The stored drive record and its units (the burst, normalised, when none is stored)."""
    drv = np.asarray(scan.drive[ai, ci], np.float64)
    if drv.size and np.any(np.isfinite(drv)):
        return drv, str(scan.drive_units)
    return burst_waveform(np.asarray(scan.time_s, np.float64), burst), "norm."
