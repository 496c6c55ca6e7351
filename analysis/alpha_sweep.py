"""Asymmetry sweep (paper Fig. 4b-c): conversion against the asymmetry factor alpha, on the DEM.

For every alpha: the chain from ``sim_backend.dem.chain_spec_for_alpha(alpha)`` (the central
cylinder's band kept, the profile tilted linearly), its quasi-bands, and one DEM run per
direction at a fixed drive amplitude (LTR at 8.92 kHz into #1, RTL at 6.63 kHz into #N, by
default). From the far cylinder's velocity: its spectrum, the output peak, the fractional
detuning ``(f_out - f_in) / f_in`` and the far/entry energy ratio; and the predicted output,
the far cylinder's band edge (:func:`analysis.bands.expected_output_Hz`).

The defaults are the paper's regime used everywhere else (the narrowband burst of
:data:`instruments.burst.NARROWBAND_CYCLES` = 21 cycles, a 30 ms window at 200 kS/s, as
``biafc simulate``): one alpha costs about 0.1 s of DEM time. Pass more alphas
for the paper's figure.

Linear reference: every alpha is also run at ``reference_amplitude`` (10 nm by default, in the
same batch), so that the sweep can tell conversion from the far cylinder filtering the burst: a
short burst's tail that reaches the far cylinder peaks at that cylinder's edge in the linear
regime too. The verdict per alpha and direction (:func:`alpha_verdict`) follows
:func:`analysis.summary.conversion_verdict` (the transmission gain over the linear run and the
detuning) and is ``"filtering"`` where the output peak lies within
``DETUNING_MIN_FRACTION x f_in`` of the linear run's peak: the detuning is what the linear run
already shows; ``"acoustic band"`` where the output peak lies below the highest acoustic cutoff
along the chain (alpha 0.6 RTL at 4 um: 2.96 kHz, under #1's 3.96 kHz).

One-band picture: the prediction (the far cylinder's edge of the first local-resonance band)
assumes that band is apart from the acoustic band ``[0, c1]`` along the whole chain. At large
alpha (from about 0.6 on the default chain) the long end's resonance-band onset falls below the
short end's acoustic cutoff (alpha 0.7: 3.78 kHz against 4.06 kHz); such alphas are flagged
(``bands_overlap``) and get the verdict ``"bands overlap"``: no converted line is reported.
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
from analysis.spectra import Spectrum, amplitude_spectrum, peak_frequency
from analysis.summary import DETUNING_MIN_FRACTION, conversion_verdict
from analysis.transmission import energy_transmission
from instruments.burst import NARROWBAND_CYCLES

__all__ = [
    "DEFAULT_ALPHAS",
    "DEFAULT_AMPLITUDE",
    "DEFAULT_DURATION_S",
    "DEFAULT_INPUTS_HZ",
    "DEFAULT_REFERENCE_AMPLITUDE",
    "AlphaSweepResult",
    "alpha_verdict",
    "bands_overlap",
    "format_alpha_sweep",
    "parse_amplitude",
    "run_alpha_sweep",
    "write_alpha_sweep",
]

#: default asymmetry factors (dimensionless): few, so the default run is cheap
DEFAULT_ALPHAS: tuple[float, ...] = (0.1, 0.2, 0.3)
#: default drive: ("displacement", metres) of the actuator wall, or ("force", newtons)
DEFAULT_AMPLITUDE: tuple[str, float] = ("displacement", 2.0e-6)
#: default linear reference: the same alphas at this drive (10 nm: linear), None for none
DEFAULT_REFERENCE_AMPLITUDE: tuple[str, float] | None = ("displacement", 10.0e-9)
#: default simulated time per run (s): the paper's window (``biafc simulate``'s default)
DEFAULT_DURATION_S = 30.0e-3
#: default recording rate (S/s)
DEFAULT_SAMPLE_RATE_HZ = 200_000.0
#: the paper's input frequencies (Hz)
DEFAULT_INPUTS_HZ: dict[str, float] = {"ltr": 8920.0, "rtl": 6630.0}
#: burst length in carrier cycles: the narrowband burst (21), as ``biafc simulate``; a shorter
#: one is broad enough that the far cylinder's filtering of its tail mimics conversion
DEFAULT_CYCLES = NARROWBAND_CYCLES


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
    ``output_Hz [K]`` (the far spectrum's peak), ``expected_Hz [K]``, ``transmission [K]``
    (E_far / E_entry), and, with a linear reference run at ``reference_amplitude``,
    ``linear_output_Hz [K]`` and ``linear_transmission [K]``. ``bands_overlap [K]``: the
    one-band picture fails at that alpha (module docstring); ``acoustic_cutoff_Hz [K]`` (the
    highest acoustic cutoff along the chain) and ``resonance_onset_Hz [K]`` (the lowest
    resonance-band onset) say by how much. The last five are empty/None when not known (a
    study's sweep)."""

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
    reference_amplitude: tuple[str, float] | None = None
    linear_output_Hz: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    linear_transmission: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    bands_overlap: NDArray[np.bool_] | None = None
    acoustic_cutoff_Hz: NDArray[np.float64] | None = None
    resonance_onset_Hz: NDArray[np.float64] | None = None
    cycles: float | None = None

    def overlap(self) -> NDArray[np.bool_]:
        """``bands_overlap`` per alpha ``[K]``; all False when not known."""
        if self.bands_overlap is None:
            return np.zeros(self.alphas.size, dtype=bool)
        return np.asarray(self.bands_overlap, dtype=bool)

    def fractional_detuning(self, direction: str) -> NDArray[np.float64]:
        """``(f_out - f_in) / f_in`` per alpha ``[K]`` (dimensionless); NaN where the bands
        overlap (no converted line is reported there)."""
        f_in = self.inputs_Hz[direction]
        return np.where(self.overlap(), np.nan, (self.output_Hz[direction] - f_in) / f_in)

    def linear_fractional_detuning(self, direction: str) -> NDArray[np.float64]:
        """The linear run's ``(f_out - f_in) / f_in`` per alpha ``[K]``; NaN without one."""
        if direction not in self.linear_output_Hz:
            return np.full(self.alphas.size, np.nan)
        f_in = self.inputs_Hz[direction]
        return (self.linear_output_Hz[direction] - f_in) / f_in

    def expected_fractional_detuning(self, direction: str) -> NDArray[np.float64]:
        """``(f_edge - f_in) / f_in`` per alpha ``[K]``: the far cylinder's edge."""
        f_in = self.inputs_Hz[direction]
        return (self.expected_Hz[direction] - f_in) / f_in

    def verdicts(self, direction: str) -> list[str]:
        """:func:`alpha_verdict` per alpha."""
        f_in = self.inputs_Hz[direction]
        lin_out = self.linear_output_Hz.get(direction)
        lin_tr = self.linear_transmission.get(direction)
        overlap = self.overlap()
        return [
            alpha_verdict(
                f_in,
                float(self.output_Hz[direction][i]),
                float(self.transmission[direction][i]),
                math.nan if lin_out is None else float(lin_out[i]),
                math.nan if lin_tr is None else float(lin_tr[i]),
                bands_overlap=bool(overlap[i]),
                acoustic_cutoff_Hz=math.nan
                if self.acoustic_cutoff_Hz is None
                else float(self.acoustic_cutoff_Hz[i]),
            )
            for i in range(self.alphas.size)
        ]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no spectra)."""

        def clean(a: NDArray[np.float64] | None) -> list[float | None] | None:
            if a is None:
                return None
            return [float(x) if math.isfinite(x) else None for x in a]

        def amp(a: tuple[str, float] | None) -> dict[str, Any] | None:
            return None if a is None else {"kind": a[0], "value_SI": a[1]}

        dirs: dict[str, Any] = {}
        for d in self.output_Hz:
            dirs[d] = {
                "output_Hz": clean(self.output_Hz[d]),
                "expected_Hz": clean(self.expected_Hz[d]),
                "fractional_detuning": clean(self.fractional_detuning(d)),
                "transmission": clean(self.transmission[d]),
                "verdict": self.verdicts(d),
            }
            if d in self.linear_output_Hz:
                dirs[d]["linear_output_Hz"] = clean(self.linear_output_Hz[d])
                dirs[d]["linear_fractional_detuning"] = clean(self.linear_fractional_detuning(d))
                dirs[d]["linear_transmission"] = clean(self.linear_transmission[d])
        return {
            "alphas": clean(self.alphas),
            "alpha_actual": clean(self.alpha_actual),
            "inputs_Hz": self.inputs_Hz,
            "amplitude": amp(self.amplitude),
            "reference_amplitude": amp(self.reference_amplitude),
            "duration_s": self.duration_s,
            "cycles": self.cycles,
            "bands_overlap": None if self.bands_overlap is None else self.overlap().tolist(),
            "acoustic_cutoff_max_Hz": clean(self.acoustic_cutoff_Hz),
            "resonance_onset_min_Hz": clean(self.resonance_onset_Hz),
            "directions": dirs,
        }


def alpha_verdict(
    f_in_Hz: float,
    output_Hz: float,
    transmission: float,
    linear_output_Hz: float = math.nan,
    linear_transmission: float = math.nan,
    *,
    bands_overlap: bool = False,
    acoustic_cutoff_Hz: float = math.nan,
) -> str:
    """``"bands overlap"`` (no one-band prediction, no converted line), ``"filtering"`` (a
    conversion by :func:`analysis.summary.conversion_verdict` whose output peak lies within
    ``DETUNING_MIN_FRACTION x f_in`` of the linear run's: the linear run already shows that
    detuning), ``"acoustic band"`` (a conversion by that verdict whose output peak lies below
    ``acoustic_cutoff_Hz``, the highest acoustic cutoff along the chain: energy in the acoustic
    band, not a line of the first local-resonance band), else that verdict (``"down"``,
    ``"up"``, ``"none"``, ``"not measured"``). The gain is ``transmission /
    linear_transmission`` (NaN without a linear run: the level rule)."""
    if bands_overlap:
        return "bands overlap"
    gain = transmission / linear_transmission if linear_transmission > 0 else math.nan
    verdict = conversion_verdict(output_Hz - f_in_Hz, f_in_Hz, transmission, gain)
    # only a line that passed can be in the acoustic band (before, a peak there read
    # "acoustic band" though nothing passed; a reviewer)
    if verdict in ("down", "up") and math.isfinite(output_Hz) and output_Hz < acoustic_cutoff_Hz:
        return "acoustic band"
    if (
        verdict in ("down", "up")
        and math.isfinite(linear_output_Hz)
        and abs(output_Hz - linear_output_Hz) < DETUNING_MIN_FRACTION * f_in_Hz
    ):
        return "filtering"
    return verdict


@dataclass
class _AlphaRun:
    """One chain's runs: ``records[(direction, is_reference)] = (far v [S], entry v [S])`` in
    m/s, the first local-resonance band's edges ``onset/cutoff [N]`` and the acoustic band's
    cutoff ``acoustic_cutoff [N]`` (NaN when the DEM stores no acoustic band), in Hz."""

    records: dict[tuple[str, bool], tuple[NDArray[np.float64], NDArray[np.float64]]]
    onset: NDArray[np.float64]
    cutoff: NDArray[np.float64]
    acoustic_cutoff: NDArray[np.float64]


def _simulate_alpha(
    alpha: float,
    inputs_Hz: dict[str, float],
    amplitude: tuple[str, float],
    duration_s: float,
    sample_rate_Hz: float,
    n_bands: int,
    cycles: float,
    reference_amplitude: tuple[str, float] | None = None,
) -> _AlphaRun:
    """DEM runs of one chain, every direction (and the linear reference) in one batch."""
    from instruments.burst import Burst
    from sim_backend import dem
    from sim_backend.dem.alpha import chain_spec_for_alpha

    chain = dem.build_chain(chain_spec_for_alpha(alpha))
    bands = dem.quasi_bands(chain, n_bands)
    acoustic, onset, cutoff = _band_edges(np.asarray(bands.onset_Hz), np.asarray(bands.cutoff_Hz))
    keys = [(d, False) for d in inputs_Hz]
    if reference_amplitude is not None:
        keys += [(d, True) for d in inputs_Hz]
    drives = []
    for d, ref in keys:
        kind, value = reference_amplitude if ref and reference_amplitude else amplitude
        drives.append(
            dem.Drive(
                direction=d,  # type: ignore[arg-type]
                kind=kind,  # type: ignore[arg-type]
                amplitude=value,
                burst=Burst(inputs_Hz[d], cycles=cycles),
            )
        )
    res = dem.simulate(chain, drives, duration_s=duration_s, sample_rate_Hz=sample_rate_Hz)
    v = np.asarray(res.velocity, dtype=np.float64)  # [R, C, S]
    n = v.shape[1]
    records = {
        key: (v[r, far_cylinder(key[0], n) - 1], v[r, entry_cylinder(key[0], n) - 1])
        for r, key in enumerate(keys)
    }
    return _AlphaRun(records, onset, cutoff, acoustic)


def _band_edges(
    onset_Hz: NDArray[np.float64], cutoff_Hz: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``(acoustic cutoff [N], resonance onset [N], resonance cutoff [N])``: the first band with
    a non-zero onset at every cylinder, and the cutoff of the band before it (NaN if none)."""
    onset = np.atleast_2d(onset_Hz)
    cutoff = np.atleast_2d(cutoff_Hz)
    if onset.shape[0] < onset.shape[1]:  # stored [B, N]
        onset, cutoff = onset.T, cutoff.T
    for b in range(onset.shape[1]):
        if np.all(onset[:, b] > 0) and np.all(cutoff[:, b] > onset[:, b]):
            below = cutoff[:, b - 1] if b > 0 else np.full(onset.shape[0], np.nan)
            return below.astype(np.float64), onset[:, b], cutoff[:, b]
    raise ValueError("the DEM chain has no band with a non-zero onset")


def bands_overlap(acoustic_cutoff_Hz: NDArray[np.float64], onset_Hz: NDArray[np.float64]) -> bool:
    """True when the one-band picture fails: some cylinder's first local-resonance band starts
    below another's acoustic cutoff (the lowest onset under the highest acoustic cutoff), so
    one frequency can pass in the acoustic band at one end and the resonance band at the other."""
    ac = acoustic_cutoff_Hz[np.isfinite(acoustic_cutoff_Hz)]
    return bool(ac.size and float(np.nanmin(onset_Hz)) < float(ac.max()))


def run_alpha_sweep(
    alphas: Sequence[float] = DEFAULT_ALPHAS,
    *,
    amplitude: tuple[str, float] = DEFAULT_AMPLITUDE,
    duration_s: float = DEFAULT_DURATION_S,
    sample_rate_Hz: float = DEFAULT_SAMPLE_RATE_HZ,
    inputs_Hz: dict[str, float] | None = None,
    n_bands: int = 3,
    cycles: float = DEFAULT_CYCLES,
    reference_amplitude: tuple[str, float] | None = DEFAULT_REFERENCE_AMPLITUDE,
) -> AlphaSweepResult:
    """Run the DEM for every alpha and both directions (see the module docstring)."""
    alphas_a = np.asarray(list(alphas), dtype=np.float64)
    if alphas_a.size == 0 or np.any(~np.isfinite(alphas_a)) or np.any(alphas_a < 0):
        raise ValueError("alphas: give at least one asymmetry factor, each finite and >= 0")
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration must be > 0 s, got {duration_s!r}")
    for what, a in (("amplitude", amplitude), ("reference amplitude", reference_amplitude)):
        if a is not None and (a[0] not in ("displacement", "force") or not a[1] > 0):
            raise ValueError(f"{what} must be a positive displacement or force, got {a}")
    inputs = dict(inputs_Hz or DEFAULT_INPUTS_HZ)
    for d in inputs:
        if d not in ("ltr", "rtl"):
            raise ValueError(f"inputs: direction must be 'ltr' or 'rtl', got {d!r}")
    k = alphas_a.size
    actual = np.full(k, np.nan)
    overlap = np.zeros(k, dtype=bool)
    acoustic_max = np.full(k, np.nan)
    onset_min = np.full(k, np.nan)

    def nans() -> dict[str, NDArray[np.float64]]:
        return {d: np.full(k, np.nan) for d in inputs}

    out, exp, tr, lin_out, lin_tr = nans(), nans(), nans(), nans(), nans()
    spectra: dict[str, list[Spectrum]] = {d: [] for d in inputs}
    f_lo, f_hi = _sweep_range(inputs)
    for i, alpha in enumerate(alphas_a):
        run = _simulate_alpha(
            float(alpha),
            inputs,
            amplitude,
            duration_s,
            sample_rate_Hz,
            n_bands,
            cycles,
            reference_amplitude,
        )
        actual[i] = asymmetry_factor(run.onset, run.cutoff)
        overlap[i] = bands_overlap(run.acoustic_cutoff, run.onset)
        if np.any(np.isfinite(run.acoustic_cutoff)):
            acoustic_max[i] = float(np.nanmax(run.acoustic_cutoff))
        onset_min[i] = float(np.nanmin(run.onset))
        for (d, ref), (v_far, v_entry) in run.records.items():
            f_in = inputs[d]
            spec = amplitude_spectrum(v_far, sample_rate_Hz)
            lo, hi = peak_search_range_Hz(f_in, run.onset, run.cutoff)
            f_lo, f_hi = min(f_lo, lo), max(f_hi, hi)  # the stored spectra cover every search
            peak = float(peak_frequency(spec.band(lo, hi), lo, hi, interior=True))
            e_ratio = float(energy_transmission(v_entry, v_far, sample_rate_Hz))
            if ref:
                lin_out[d][i], lin_tr[d][i] = peak, e_ratio
                continue
            out[d][i], tr[d][i] = peak, e_ratio
            exp[d][i] = expected_output_Hz(f_in, d, run.onset, run.cutoff)
            spectra[d].append(spec)
    freq = spectra[next(iter(inputs))][0].band(f_lo, f_hi).freq_Hz
    result = AlphaSweepResult(alphas_a, actual, inputs, amplitude, duration_s, freq)
    result.reference_amplitude = reference_amplitude
    result.bands_overlap = overlap
    result.acoustic_cutoff_Hz = acoustic_max
    result.resonance_onset_Hz = onset_min
    result.cycles = float(cycles)
    for d in inputs:
        result.magnitude[d] = np.vstack([s.band(f_lo, f_hi).magnitude for s in spectra[d]])
        result.output_Hz[d] = out[d]
        result.expected_Hz[d] = exp[d]
        result.transmission[d] = tr[d]
        if reference_amplitude is not None:
            result.linear_output_Hz[d] = lin_out[d]
            result.linear_transmission[d] = lin_tr[d]
    return result


def _sweep_range(inputs: dict[str, float]) -> tuple[float, float]:
    """Least frequencies kept in the sweep's spectra: 0.5 to 1.5 times the inputs' span (Hz);
    widened to every alpha's peak search range (:func:`analysis.bands.peak_search_range_Hz`)."""
    return 0.5 * min(inputs.values()), 1.5 * max(inputs.values())


def format_alpha_sweep(result: AlphaSweepResult) -> str:
    """The sweep as a text table: alpha, direction, f_out, detuning %, predicted %, E ratio,
    with a linear reference its detuning % and the gain, and the verdict
    (:func:`alpha_verdict`); alphas where the bands overlap show no output line."""
    has_lin = bool(result.linear_output_Hz)
    head = (
        f"{'alpha':>6} {'actual':>6} {'dir':4} {'f_out kHz':>9} {'df/f %':>7} "
        f"{'edge %':>7} {'E_far/E_in':>10}"
    )
    if has_lin:
        head += f" {'lin df/f %':>10} {'gain':>8}"
    lines = [head + "  verdict"]
    overlap = result.overlap()
    for i, alpha in enumerate(result.alphas):
        for d in result.output_Hz:
            fd = result.fractional_detuning(d)[i] * 100
            ed = result.expected_fractional_detuning(d)[i] * 100
            peak = result.output_Hz[d][i]  # none inside the search range: "-", as elsewhere
            shown = (
                f"{peak / 1e3:9.3f} {fd:7.2f}"
                if np.isfinite(peak) and not overlap[i]
                else f"{'-':>9} {'-':>7}"
            )
            line = (
                f"{alpha:6.3f} {result.alpha_actual[i]:6.3f} {d:4} "
                f"{shown} {ed:7.2f} {result.transmission[d][i]:10.3g}"
            )
            if has_lin:
                ld = result.linear_fractional_detuning(d)[i] * 100
                lt = result.linear_transmission[d][i]
                gain = result.transmission[d][i] / lt if lt > 0 else math.nan
                ls = f"{ld:10.2f}" if np.isfinite(ld) else f"{'-':>10}"
                line += f" {ls} {gain:8.3g}"
            verdict = result.verdicts(d)[i]
            if verdict == "bands overlap" and result.acoustic_cutoff_Hz is not None:
                verdict += (
                    f" (resonance onset {result.resonance_onset_Hz[i] / 1e3:.2f} kHz"  # type: ignore[index]
                    f" < acoustic cutoff {result.acoustic_cutoff_Hz[i] / 1e3:.2f} kHz)"
                )
            elif verdict == "acoustic band" and result.acoustic_cutoff_Hz is not None:
                verdict += f" (below {result.acoustic_cutoff_Hz[i] / 1e3:.2f} kHz)"
            lines.append(f"{line}  {verdict}")
    if overlap.any():
        lines.append(
            "bands overlap: the one-band picture fails (a cylinder's resonance band starts below "
            "another's acoustic cutoff); no converted line is reported there"
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
