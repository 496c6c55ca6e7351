"""The model's prediction for the point being measured (the GUI's "model" overlay), no Qt.

:class:`ModelOverlay` knows what the bench does to the chain (each direction's burst, the
amplifier gain and piezo stroke that turn a protocol amplitude into the actuator's drive, the
vibrometer's clip level) and the chain; :meth:`ModelOverlay.predict` runs the DEM once per
(direction, amplitude, record) for every cylinder and caches it, so the spectrum and the
spatial-frequency map of every later point at that amplitude cost nothing.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal, cast

import numpy as np
from numpy.typing import NDArray

from analysis.model_run import _on_time_axis, model_duration_s
from analysis.spectra import amplitude_spectrum, peak_frequency
from instruments.burst import Burst
from sim_backend.dem import ChainSpec, Drive, build_chain, simulate

__all__ = ["ModelOverlay", "OverlayPrediction"]


@dataclass(frozen=True)
class OverlayPrediction:
    """Every cylinder's predicted spectrum for one (direction, amplitude): ``freq_Hz [F]``,
    ``magnitude [N, F]`` (m, cylinder order 1..N), ``peak_Hz [N]`` (in ``f_range_Hz``)."""

    freq_Hz: NDArray[np.float64]
    magnitude: NDArray[np.float64]
    peak_Hz: NDArray[np.float64]


class ModelOverlay:
    """Predictions for the live views.

    Parameters
    ----------
    chain_spec: the chain model.
    bursts: direction -> burst shape.
    kind: ``"displacement"`` or ``"force"`` (the actuator's).
    gain_V_per_V, stroke_SI_per_V: the amplifier gain and the piezo's stroke (m/V, or N/V);
        ``None`` when amplitudes are the drive itself (m or N).
    bench_stroke_SI_per_V: the stroke the protocol's metres were converted with (default: the
        same as ``stroke_SI_per_V``).
    clip_m_per_s: the vibrometer's clip level (``inf``: none).
    """

    def __init__(
        self,
        chain_spec: ChainSpec,
        bursts: Mapping[str, Burst],
        *,
        kind: str = "displacement",
        gain_V_per_V: float | None = None,
        stroke_SI_per_V: float | None = None,
        bench_stroke_SI_per_V: float | None = None,
        clip_m_per_s: float = math.inf,
    ) -> None:
        self.chain_spec = chain_spec
        self.bursts = dict(bursts)
        self.kind = cast(Literal["displacement", "force"], kind)
        self.gain = gain_V_per_V
        self.stroke = stroke_SI_per_V
        self.bench_stroke = bench_stroke_SI_per_V or stroke_SI_per_V
        self.clip = clip_m_per_s
        self._cache: dict[tuple[Any, ...], OverlayPrediction] = {}
        self._lock = threading.Lock()

    @classmethod
    def for_bench(cls, bench: Any, protocol: Any, chain_spec: ChainSpec) -> ModelOverlay:
        """From a validated bench (``protocols.bench.BenchSpec``) and protocol."""
        from instruments.polytec import parse_sensitivity

        amp = bench.amplifier
        stroke = amp.piezo_stroke if amp.kind == "displacement" else amp.force_per_volt
        try:
            fs = 10.0 if bench.simulation is None else float(bench.simulation.vibrometer_full_scale)
            clip = parse_sensitivity(bench.vibrometer.range) * min(fs, bench.daq.velocity_range)
        except Exception:
            clip = math.inf
        bursts = {d: protocol.burst[d].burst() for d in protocol.direction_list}
        return cls(
            chain_spec, bursts, kind=amp.kind, gain_V_per_V=amp.gain, stroke_SI_per_V=stroke,
            clip_m_per_s=clip,
        )  # fmt: skip

    @classmethod
    def for_run(cls, run: Any, chain_spec: ChainSpec | None = None) -> ModelOverlay:
        """From a run file (``protocols.runfile.RunData``): its bursts, bench and chain."""
        from analysis.model_run import chain_spec_of_run, run_setup

        s = run_setup(run)
        kinds = {ds.kind for ds in s.directions.values()} or {"displacement"}
        return cls(
            chain_spec if chain_spec is not None else chain_spec_of_run(run),
            {d: ds.burst for d, ds in s.directions.items()},
            kind=kinds.pop(),
            gain_V_per_V=s.amplifier_gain_V_per_V,
            stroke_SI_per_V=s.stroke_m_per_V,
            bench_stroke_SI_per_V=s.bench_stroke_m_per_V,
            clip_m_per_s=s.clip_m_per_s,
        )

    def drive_SI(self, amplitude: float, units: str) -> float:
        """What reached the chain (m or N) for a protocol amplitude in ``units``."""
        if units == "V" and self.gain is not None and self.stroke is not None:
            return 0.5 * amplitude * self.gain * self.stroke
        if units == "m" and self.stroke is not None and self.bench_stroke is not None:
            return amplitude * self.stroke / self.bench_stroke
        return amplitude

    def cached(
        self, direction: str, amplitude: float, units: str, time_s: NDArray[np.float64]
    ) -> OverlayPrediction | None:
        """The prediction if it was computed already (never runs the model)."""
        with self._lock:
            return self._cache.get(self._key(direction, amplitude, units, time_s))

    @staticmethod
    def _key(direction: str, amplitude: float, units: str, t: NDArray[np.float64]) -> tuple:  # type: ignore[type-arg]
        return (direction, float(amplitude), units, int(t.size), float(t[0]), float(t[-1]))

    def predict(
        self,
        direction: str,
        amplitude: float,
        units: str,
        time_s: NDArray[np.float64],
        f_range_Hz: tuple[float, float] = (0.0, math.inf),
    ) -> OverlayPrediction:
        """Every cylinder's spectrum for the point (DEM, the record's time axis, clipped)."""
        key = self._key(direction, amplitude, units, time_s)
        with self._lock:
            hit = self._cache.get(key)
        if hit is not None:
            return hit
        chain = build_chain(self.chain_spec)
        rate = 1.0 / float(np.median(np.diff(time_s)))
        drive = Drive(
            cast(Literal["ltr", "rtl"], direction),
            self.kind,
            self.drive_SI(amplitude, units),
            self.bursts[direction],
        )
        res = simulate(
            chain,
            [drive],
            duration_s=model_duration_s(float(time_s[-1]), rate),
            sample_rate_Hz=rate,
            record=("velocity",),
        )
        v = _on_time_axis(res.time_s, res.velocity[0], np.asarray(time_s, dtype=np.float64))
        if math.isfinite(self.clip):
            v = np.clip(v, -self.clip, self.clip)
        spec = amplitude_spectrum(v, rate)
        peaks = peak_frequency(spec, *f_range_Hz, interior=True)
        out = OverlayPrediction(spec.freq_Hz, spec.magnitude, np.asarray(peaks, np.float64))
        with self._lock:
            self._cache[key] = out
        return out
