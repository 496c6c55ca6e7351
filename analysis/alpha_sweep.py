"""Asymmetry sweep (paper Fig. 4b-c): conversion against the asymmetry factor alpha, on the DEM.

For every alpha: the chain from ``sim_backend.dem.chain_spec_for_alpha(alpha)`` (the central
cylinder's band kept, the profile tilted linearly), its quasi-bands, and one DEM run per
direction at a fixed drive amplitude (LTR at 8.92 kHz into #1, RTL at 6.63 kHz into #N, by
default). From the far cylinder's velocity: its spectrum, the output peak, the fractional
detuning ``(f_out - f_in) / f_in`` and the far/entry energy ratio; and the predicted output,
the far cylinder's band edge (:func:`analysis.bands.expected_output_Hz`).

The defaults are cheap (three alphas, a short record) so that a test can run them; pass more
alphas and a longer ``duration_s`` for the paper's figure.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from analysis.bands import (
    asymmetry_factor,
    entry_cylinder,
    expected_output_Hz,
    far_cylinder,
    peak_search_range_Hz,
)
from analysis.spectra import amplitude_spectrum, peak_frequency
from analysis.transmission import energy_transmission

__all__ = [
    "DEFAULT_ALPHAS",
    "DEFAULT_AMPLITUDE",
    "DEFAULT_DURATION_S",
    "DEFAULT_INPUTS_HZ",
    "AlphaSweepResult",
    "format_alpha_sweep",
    "parse_amplitude",
    "run_alpha_sweep",
    "write_alpha_sweep",
]

#: default asymmetry factors (dimensionless): few, so the default run is cheap
DEFAULT_ALPHAS: tuple[float, ...] = (0.1, 0.2, 0.3)
#: default drive: ("displacement", metres) of the actuator wall, or ("force", newtons)
DEFAULT_AMPLITUDE: tuple[str, float] = ("displacement", 2.0e-6)
#: default simulated time per run (s)
DEFAULT_DURATION_S = 8.0e-3
#: default recording rate (S/s)
DEFAULT_SAMPLE_RATE_HZ = 200_000.0
#: the paper's input frequencies (Hz)
DEFAULT_INPUTS_HZ: dict[str, float] = {"ltr": 8920.0, "rtl": 6630.0}
#: burst length in carrier cycles (10: narrow enough that the output is not just the far
#: cylinder filtering a broad burst's tail)
DEFAULT_CYCLES = 10.0


def parse_amplitude(text: str) -> tuple[str, float]:
    """``"2um"`` -> ``("displacement", 2e-6)``; ``"12N"`` -> ``("force", 12.0)``.

    Raises ValueError (one line) for a number without a length or force unit.
    """
    from instruments.units import UnitError, parse_quantity

    try:
        return "displacement", parse_quantity(text, "length", field="amplitude")
    except UnitError:
        pass
    try:
        return "force", parse_quantity(text, "force", field="amplitude")
    except UnitError as exc:
        raise ValueError(
            f"amplitude {text!r}: give a displacement (e.g. 2um) or a force (e.g. 12N)"
        ) from exc


@dataclass
class AlphaSweepResult:
    """Shapes: ``alphas [K]`` (requested), ``alpha_actual [K]`` (from the built chain's bands),
    ``freq_Hz [F]``; per direction: ``magnitude [K, F]`` (far-cylinder velocity spectrum, m),
    ``output_Hz [K]``, ``expected_Hz [K]``, ``transmission [K]`` (E_far / E_entry)."""

    alphas: NDArray[np.float64]
    alpha_actual: NDArray[np.float64]
    inputs_Hz: dict[str, float]
    amplitude: tuple[str, float]
    duration_s: float
    freq_Hz: NDArray[np.float64]
    magnitude: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    output_Hz: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    expected_Hz: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    transmission: dict[str, NDArray[np.float64]] = field(default_factory=dict)

    def fractional_detuning(self, direction: str) -> NDArray[np.float64]:
        """``(f_out - f_in) / f_in`` per alpha ``[K]`` (dimensionless)."""
        f_in = self.inputs_Hz[direction]
        return (self.output_Hz[direction] - f_in) / f_in

    def expected_fractional_detuning(self, direction: str) -> NDArray[np.float64]:
        """``(f_edge - f_in) / f_in`` per alpha ``[K]``: the far cylinder's edge."""
        f_in = self.inputs_Hz[direction]
        return (self.expected_Hz[direction] - f_in) / f_in

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no spectra)."""

        def clean(a: NDArray[np.float64]) -> list[float | None]:
            return [float(x) if math.isfinite(x) else None for x in a]

        return {
            "alphas": clean(self.alphas),
            "alpha_actual": clean(self.alpha_actual),
            "inputs_Hz": self.inputs_Hz,
            "amplitude": {"kind": self.amplitude[0], "value_SI": self.amplitude[1]},
            "duration_s": self.duration_s,
            "directions": {
                d: {
                    "output_Hz": clean(self.output_Hz[d]),
                    "expected_Hz": clean(self.expected_Hz[d]),
                    "fractional_detuning": clean(self.fractional_detuning(d)),
                    "transmission": clean(self.transmission[d]),
                }
                for d in self.output_Hz
            },
        }


def _simulate_alpha(
    alpha: float,
    inputs_Hz: dict[str, float],
    amplitude: tuple[str, float],
    duration_s: float,
    sample_rate_Hz: float,
    n_bands: int,
    cycles: float,
) -> tuple[dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]], NDArray[np.float64],
           NDArray[np.float64]]:  # fmt: skip
    """DEM runs of one chain, every direction in one batch.

    Returns ``({direction: (far velocity [S], entry velocity [S])}, onset_Hz [N], cutoff_Hz [N])``
    with velocities in m/s and the edges of the first local-resonance band.
    """
    from instruments.burst import Burst
    from sim_backend import dem
    from sim_backend.dem.alpha import chain_spec_for_alpha

    chain = dem.build_chain(chain_spec_for_alpha(alpha))
    bands = dem.quasi_bands(chain, n_bands)
    onset, cutoff = _resonance_edges(np.asarray(bands.onset_Hz), np.asarray(bands.cutoff_Hz))
    kind, value = amplitude
    directions = list(inputs_Hz)
    drives = [
        dem.Drive(
            direction=d,  # type: ignore[arg-type]
            kind=kind,  # type: ignore[arg-type]
            amplitude=value,
            burst=Burst(inputs_Hz[d], cycles=cycles),
        )
        for d in directions
    ]
    res = dem.simulate(chain, drives, duration_s=duration_s, sample_rate_Hz=sample_rate_Hz)
    v = np.asarray(res.velocity, dtype=np.float64)  # [R, C, S]
    n = v.shape[1]
    out = {}
    for r, d in enumerate(directions):
        out[d] = (v[r, far_cylinder(d, n) - 1], v[r, entry_cylinder(d, n) - 1])
    return out, onset, cutoff


def _resonance_edges(
    onset_Hz: NDArray[np.float64], cutoff_Hz: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    onset = np.atleast_2d(onset_Hz)
    cutoff = np.atleast_2d(cutoff_Hz)
    if onset.shape[0] < onset.shape[1]:  # stored [B, N]
        onset, cutoff = onset.T, cutoff.T
    for b in range(onset.shape[1]):
        if np.all(onset[:, b] > 0) and np.all(cutoff[:, b] > onset[:, b]):
            return onset[:, b], cutoff[:, b]
    raise ValueError("the DEM chain has no band with a non-zero onset")


def run_alpha_sweep(
    alphas: Sequence[float] = DEFAULT_ALPHAS,
    *,
    amplitude: tuple[str, float] = DEFAULT_AMPLITUDE,
    duration_s: float = DEFAULT_DURATION_S,
    sample_rate_Hz: float = DEFAULT_SAMPLE_RATE_HZ,
    inputs_Hz: dict[str, float] | None = None,
    n_bands: int = 3,
    cycles: float = DEFAULT_CYCLES,
) -> AlphaSweepResult:
    """Run the DEM for every alpha and both directions (see the module docstring)."""
    alphas_a = np.asarray(list(alphas), dtype=np.float64)
    if alphas_a.size == 0 or np.any(~np.isfinite(alphas_a)) or np.any(alphas_a < 0):
        raise ValueError("alphas: give at least one asymmetry factor, each finite and >= 0")
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration must be > 0 s, got {duration_s!r}")
    if amplitude[0] not in ("displacement", "force") or not amplitude[1] > 0:
        raise ValueError(f"amplitude must be a positive displacement or force, got {amplitude}")
    inputs = dict(inputs_Hz or DEFAULT_INPUTS_HZ)
    for d in inputs:
        if d not in ("ltr", "rtl"):
            raise ValueError(f"inputs: direction must be 'ltr' or 'rtl', got {d!r}")
    k = alphas_a.size
    f_range = _sweep_range(inputs)
    actual = np.full(k, np.nan)
    out = {d: np.full(k, np.nan) for d in inputs}
    exp = {d: np.full(k, np.nan) for d in inputs}
    tr = {d: np.full(k, np.nan) for d in inputs}
    rows: dict[str, list[NDArray[np.float64]]] = {d: [] for d in inputs}
    freq = np.zeros(0)
    for i, alpha in enumerate(alphas_a):
        records, onset, cutoff = _simulate_alpha(
            float(alpha), inputs, amplitude, duration_s, sample_rate_Hz, n_bands, cycles
        )
        actual[i] = asymmetry_factor(onset, cutoff)
        for d, (v_far, v_entry) in records.items():
            f_in = inputs[d]
            spec = amplitude_spectrum(v_far, sample_rate_Hz).band(*f_range)
            lo, hi = peak_search_range_Hz(f_in, onset, cutoff)
            out[d][i] = float(peak_frequency(spec, lo, hi, interior=True))
            exp[d][i] = expected_output_Hz(f_in, d, onset, cutoff)
            tr[d][i] = float(energy_transmission(v_entry, v_far, sample_rate_Hz))
            rows[d].append(spec.magnitude)
            freq = spec.freq_Hz
    result = AlphaSweepResult(alphas_a, actual, inputs, amplitude, duration_s, freq)
    for d in inputs:
        result.magnitude[d] = np.vstack(rows[d])
        result.output_Hz[d] = out[d]
        result.expected_Hz[d] = exp[d]
        result.transmission[d] = tr[d]
    return result


def _sweep_range(inputs: dict[str, float]) -> tuple[float, float]:
    """Frequencies kept in the sweep's spectra: 0.5 to 1.5 times the inputs' span (Hz)."""
    return 0.5 * min(inputs.values()), 1.5 * max(inputs.values())


def format_alpha_sweep(result: AlphaSweepResult) -> str:
    """The sweep as a text table: alpha, direction, f_out, detuning %, predicted %, E ratio."""
    lines = [
        f"{'alpha':>6} {'actual':>6} {'dir':4} {'f_out kHz':>9} {'df/f %':>7} "
        f"{'edge %':>7} {'E_far/E_in':>10}"
    ]
    for i, alpha in enumerate(result.alphas):
        for d in result.output_Hz:
            fd = result.fractional_detuning(d)[i] * 100
            ed = result.expected_fractional_detuning(d)[i] * 100
            peak = result.output_Hz[d][i]  # none inside the search range: "-", as elsewhere
            shown = f"{peak / 1e3:9.3f} {fd:7.2f}" if np.isfinite(peak) else f"{'-':>9} {'-':>7}"
            lines.append(
                f"{alpha:6.3f} {result.alpha_actual[i]:6.3f} {d:4} "
                f"{shown} {ed:7.2f} {result.transmission[d][i]:10.3g}"
            )
    return "\n".join(lines)


def write_alpha_sweep(result: AlphaSweepResult, out_dir: str | Path) -> list[Path]:
    """Write ``alpha_sweep.png/.pdf`` and ``alpha_sweep.json`` into ``out_dir``."""
    import json

    from analysis.plots.alpha_plot import plot_alpha_sweep
    from analysis.plots.style import save_figure

    out = Path(out_dir)
    paths = save_figure(plot_alpha_sweep(result), out, "alpha_sweep")
    js = out / "alpha_sweep.json"
    js.write_text(json.dumps(result.to_dict(), indent=2, allow_nan=False) + "\n")
    return [*paths, js]
