"""The short summary of a run: per direction and amplitude, input and output peak frequency,
detuning and transmission, and the verdict on frequency conversion.

Verdict rules (one place). A point converts when the nonlinearity carries energy to the far
cylinder and its output peak has moved from the input:

- energy: the transmission gain over the sweep's smallest amplitude (the linear reference, see
  :mod:`analysis.sweep`) is at least ``GAIN_MIN``; with a single amplitude (no reference) the
  transmission itself must reach ``TRANSMISSION_MIN``;
- frequency: ``|detuning| >= DETUNING_MIN_FRACTION * f_in``;

then ``"down"`` (output below input) or ``"up"``; otherwise ``"none"``. Points where the far or
the entry cylinder was not measured get ``"not measured"``, ``"failed: entry point"`` (or
far) where that point was measured and failed, and ``"not scanned: far cylinder 31"`` (or
entry) where the scan does not hold that cylinder.

Noise (:mod:`analysis.noise_floor`): a point whose far record holds, within the band where the
signal can be, no more than the noise of its own pre-trigger samples there is ``"none"``, and
says so (``at_noise_floor``, its transmission only as an upper bound, no output peak): nothing
passed that the bench could see. When the linear reference is itself at the noise floor, every
gain is a lower bound; a point that stands above the noise and has moved from the input, but
whose lower bound stays below ``GAIN_MIN``, is ``"undetermined"``: the run cannot tell whether
the nonlinearity let it through. A point above the noise without a line inside the search range
(its largest value on the range's edge) is ``"undetermined"`` when it passes by the energy rule
(or may, its gain a lower bound), else ``"none"``.

Why a gain and not a level: a short burst is broad, and in the linear regime its tail near the
frequency where the end cylinders' bands nearly meet leaks through (about 1e-3 of the energy
for a 5-cycle burst on the default chain) and peaks there, away from the input; only the growth
of the transmission with amplitude tells nonlinear conversion from that leak.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from analysis.display import amplitude_label
from analysis.sweep import AmplitudeSweep, amplitude_sweep, output_peak_definition
from protocols.runfile import PointState, RunData, ScanData

__all__ = [
    "DETUNING_MIN_FRACTION",
    "GAIN_MIN",
    "TRANSMISSION_MIN",
    "conversion_verdict",
    "format_summary",
    "is_conversion",
    "summarize",
    "summary_rows",
    "verdict_reason",
    "write_summary",
]

#: least transmission gain over the linear reference for a point to count as transmitted
GAIN_MIN = 3.0
#: least far/entry energy ratio when no linear reference exists (one amplitude)
TRANSMISSION_MIN = 1.0e-2
#: least |detuning| / input frequency for a point to count as converted
DETUNING_MIN_FRACTION = 0.02


def conversion_verdict(
    detuning_Hz: float, input_Hz: float, transmission: float, gain: float = math.nan
) -> str:
    """``"down"``, ``"up"``, ``"none"`` or ``"not measured"`` (see the module docstring).

    ``gain`` is the transmission gain over the linear reference (NaN when there is none).
    """
    if not (math.isfinite(detuning_Hz) and math.isfinite(transmission)):
        return "not measured"
    passes = gain >= GAIN_MIN if math.isfinite(gain) else transmission >= TRANSMISSION_MIN
    if not passes or abs(detuning_Hz) < DETUNING_MIN_FRACTION * input_Hz:
        return "none"
    return "down" if detuning_Hz < 0 else "up"


def is_conversion(verdict: str) -> bool:
    """Whether a summary row's ``conversion`` verdict is a conversion (``"down"``/``"up"``)."""
    return verdict in ("down", "up")


def verdict_reason(row: dict[str, Any]) -> str:
    """The verdict of a :func:`summary_rows` row in words, with the numbers that decided it, to
    print beside its output line: ``"not converted: gain 1.2 over the linear reference, ..."``.
    With a single amplitude there is no linear reference, and the verdict is the
    one-amplitude rule's (the level and the detuning), said as such: a broad burst's linear
    leak can pass it (a 2-cycle LTR burst gives E_far/E_in 0.016 at 1 nm and at 10 nm alike; a
    reviewer), so one run never says "converted", only what the rule gives and that a smaller
    amplitude (``biafc regime``) tells the two apart."""
    verdict = str(row["conversion"])
    t, g = row.get("transmission"), row.get("transmission_gain")
    f_in, det = row.get("input_Hz"), row.get("detuning_Hz")
    if row.get("at_noise_floor"):
        return "not converted: the far end is at the noise floor"
    if t is None or f_in is None or det is None or verdict not in ("down", "up", "none"):
        return verdict
    moved = f"|detuning| {abs(det) / f_in:.1%} of f_in"
    if g is None:  # one amplitude: the one-amplitude rule, never a conversion outright
        energy = f"E_far/E_in {t:.3g}"
        tell = "one run cannot tell a conversion from a linear leak: compare a smaller amplitude"
        if is_conversion(verdict):
            return (
                f"{verdict} by the one-amplitude rule ({energy} >= {TRANSMISSION_MIN:g}, {moved} "
                f">= {DETUNING_MIN_FRACTION:.0%}); {tell} (biafc regime)"
            )
        if t < TRANSMISSION_MIN:
            return (
                f"not converted by the one-amplitude rule: {energy}, below "
                f"{TRANSMISSION_MIN:g} ({tell}: biafc regime)"
            )
        return (
            f"not converted by the one-amplitude rule: {moved}, below {DETUNING_MIN_FRACTION:.0%}"
        )
    bound = ">=" if row.get("gain_is_lower_bound") else ""
    energy = f"gain {bound}{g:.3g} over the linear reference"
    if is_conversion(verdict):
        return (
            f"converted {verdict}: {energy} >= {GAIN_MIN:g}, {moved} >= {DETUNING_MIN_FRACTION:.0%}"
        )
    if not g >= GAIN_MIN:
        return f"not converted: {energy}, below {GAIN_MIN:g}"
    return f"not converted: {moved}, below {DETUNING_MIN_FRACTION:.0%}"


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _failed_ends(sweep: AmplitudeSweep, scan: ScanData | None, a: int) -> str | None:
    """Why the conversion at amplitude ``a`` cannot be judged, when the ``scan`` tells:
    ``"not scanned: far cylinder 31"`` (or entry) when the scan does not hold that cylinder,
    ``"failed: far point"`` (entry, entry and far) when it failed; None otherwise."""
    if scan is None:
        return None
    hit, absent = [], []
    for name, number in (("entry", sweep.entry), ("far", sweep.far)):
        c = np.nonzero(scan.cylinders == number)[0]
        if not c.size:
            absent.append(f"{name} cylinder {number}")
        elif scan.done[a, int(c[0])] == PointState.FAILED:
            hit.append(name)
    if absent:
        return "not scanned: " + " and ".join(absent)
    return f"failed: {' and '.join(hit)} point" if hit else None


def summary_rows(sweep: AmplitudeSweep, scan: ScanData | None = None) -> list[dict[str, Any]]:
    """One row per amplitude of a sweep (JSON-ready: NaN becomes None); with the ``scan`` the
    sweep was made of, a conversion that cannot be judged because the entry or far point
    failed says so ("failed: far point"), not "not measured"."""
    rows = []
    for a, amp in enumerate(sweep.amplitudes):
        floor = bool(sweep.at_noise_floor[a])
        gain = float(sweep.transmission_gain[a])
        detuning = float(sweep.detuning_Hz[a])
        verdict = conversion_verdict(
            detuning, float(sweep.input_Hz[a]), float(sweep.transmission[a]), gain
        )
        measured = math.isfinite(float(sweep.transmission[a]))
        if floor:
            verdict = "none"
        elif measured and not math.isfinite(float(sweep.output_Hz[a])):
            # measured, no line inside the search range (its largest value on an edge): it
            # passed (or may have: a lower-bound gain) but no converted line can be named
            tr = float(sweep.transmission[a])
            passes = gain >= GAIN_MIN if math.isfinite(gain) else tr >= TRANSMISSION_MIN
            maybe = sweep.reference_is_bound and math.isfinite(gain)
            verdict = "undetermined" if passes or maybe else "none"
        elif verdict == "none" and sweep.reference_is_bound and math.isfinite(gain):
            moved = abs(detuning) >= DETUNING_MIN_FRACTION * float(sweep.input_Hz[a])
            verdict = "undetermined" if moved and gain < GAIN_MIN else verdict
        why = _failed_ends(sweep, scan, a) if verdict == "not measured" else None
        if why is not None:
            verdict = why
        rows.append(
            {
                "direction": sweep.direction,
                "amplitude": float(amp),
                "amplitude_units": sweep.amplitude_units,
                "input_Hz": _num(sweep.input_Hz[a]),
                "output_Hz": _num(sweep.output_Hz[a]),
                "detuning_Hz": _num(sweep.detuning_Hz[a]),
                "transmission": _num(sweep.transmission[a]),
                "signal_transmission": _num(sweep.signal_transmission[a]),
                "transmission_gain": _num(sweep.transmission_gain[a]),
                "gain_is_lower_bound": bool(sweep.reference_is_bound),
                "far_noise_ratio": _num(sweep.far_noise_ratio[a]),
                "at_noise_floor": floor,
                "transmission_upper_bound": _num(sweep.transmission_bound[a]),
                "expected_output_Hz": _num(sweep.expected_Hz),
                "conversion": verdict,
            }
        )
    return rows


def summarize(run: RunData, sweeps: Mapping[str, AmplitudeSweep] | None = None) -> dict[str, Any]:
    """Summary of a run: ``{"file", "status", "backend", "far_cylinder", "output_peak",
    "points", "noise_unknown", "noise_band_Hz", "rows": [...]}``; ``output_peak`` says per
    direction what ``output_Hz`` (f_out) is; ``noise_unknown``: the directions whose measured
    far records have no pre-trigger samples to estimate the noise from; ``noise_band_Hz``: per
    direction, the band over which the far record is set against its noise;
    ``noise_over_whole_record``: the directions whose pre-trigger was too short for that band,
    set against their noise over the whole record.

    ``rows`` holds one dict per direction and amplitude (see :func:`summary_rows`).
    ``sweeps``: each direction's :func:`analysis.sweep.amplitude_sweep` where the caller has it
    already (computed here otherwise).
    """
    rows: list[dict[str, Any]] = []
    far: dict[str, int] = {}
    peak: dict[str, str] = {}
    points: dict[str, dict[str, int]] = {}
    unknown: list[str] = []
    noise_band: dict[str, list[float]] = {}
    whole_record: list[str] = []
    for direction, scan in run.scans.items():
        sweep = sweeps[direction] if sweeps is not None else amplitude_sweep(scan, run.chain)
        noise_band[direction] = [float(f) for f in sweep.signal_band_Hz]
        if sweep.noise_over_whole_record:
            whole_record.append(direction)
        if sweep.far_measured.any() and not sweep.noise_known:
            unknown.append(direction)
        far[direction] = sweep.far
        peak[direction] = output_peak_definition(sweep)
        rows.extend(summary_rows(sweep, scan))
        points[direction] = {
            "measured": int(np.count_nonzero(scan.done == PointState.DONE)),
            "failed": int(np.count_nonzero(scan.done == PointState.FAILED)),
            "pending": int(np.count_nonzero(scan.done == PointState.PENDING)),
        }
    return {
        "file": str(run.path),
        "status": run.status,
        "backend": run.backend,
        "far_cylinder": far,
        "output_peak": peak,
        "points": points,
        "noise_unknown": unknown,
        "noise_band_Hz": noise_band,
        "noise_over_whole_record": whole_record,
        "rows": rows,
    }


def format_summary(summary: dict[str, Any]) -> str:
    """The summary as a plain-text table (kHz, percent)."""

    def khz(v: float | None) -> str:
        return "-" if v is None else f"{v / 1e3:.3f}"

    counts = summary.get("points", {})
    lines = [
        f"{summary['file']}  status={summary['status']}  backend={summary['backend']}",
        *(
            f"points {d}: {c['measured']} measured, {c['failed']} failed, {c['pending']} not "
            "measured (the maps hatch failed and unmeasured points, the sweeps mark them x)"
            for d, c in counts.items()
            if c["failed"] or c["pending"]
        ),
        f"{'dir':4} {'amplitude':>12} {'f_in kHz':>9} {'f_out kHz':>9} {'detune kHz':>10} "
        f"{'expect kHz':>10} {'E_far/E_in':>10} {'E_sig/E_in':>10} {'gain':>7}  conversion",
    ]
    for r in summary["rows"]:
        tr = "-" if r["transmission"] is None else f"{r['transmission']:.3g}"
        sig = r.get("signal_transmission")
        signal = "-" if sig is None or r["transmission"] is None else f"{sig:.3g}"
        if r.get("at_noise_floor") and r.get("transmission_upper_bound") is not None:
            signal = f"<{r['transmission_upper_bound']:.3g}"
        gain = "-" if r["transmission_gain"] is None else f"{r['transmission_gain']:.3g}"
        if r["transmission_gain"] is not None and r.get("gain_is_lower_bound"):
            gain = f">={r['transmission_gain']:.3g}"
        amp = amplitude_label(r["amplitude"], r["amplitude_units"])
        lines.append(
            f"{r['direction']:4} {amp:>12} {khz(r['input_Hz']):>9} {khz(r['output_Hz']):>9} "
            f"{khz(r['detuning_Hz']):>10} {khz(r['expected_output_Hz']):>10} {tr:>10} "
            f"{signal:>10} {gain:>7}  {r['conversion']}"
        )
    whole = set(summary.get("noise_over_whole_record", []))
    unknown = set(summary.get("noise_unknown", []))
    bands = ", ".join(
        f"{d}: no noise estimate, E_sig = E_far"
        if d in unknown
        else f"{d}: the whole record, its pre-trigger too short for a band's noise"
        if d in whole
        else f"{d} {lo / 1e3:.2f}-{hi / 1e3:.2f} kHz"
        for d, (lo, hi) in summary.get("noise_band_Hz", {}).items()
    )
    if any(r.get("signal_transmission") is not None for r in summary["rows"]):
        lines.append(
            "E_far/E_in: the far end's energy over the entry's, whole records (noise included); "
            f"E_sig/E_in: the far end's signal, its energy in the band where it can be ({bands}) "
            "less its pre-trigger noise's there; the gains are of E_sig"
        )
    if any(r.get("at_noise_floor") for r in summary["rows"]):
        lines.append(
            "<x: the far end held less than 4x the energy its own pre-trigger noise gives "
            "within that band; its signal is at most x and no output peak is given"
        )
    if any(r.get("gain_is_lower_bound") for r in summary["rows"]):
        lines.append(
            ">=x: the smallest amplitude is at the noise floor, so the linear reference is an "
            "upper bound and the gains lower bounds"
        )
    for direction in summary.get("noise_unknown", []):
        lines.append(
            f"{direction}: no noise estimate (its records have fewer than 16 pre-trigger "
            "samples: acquisition.pre_trigger); a far end at the noise floor cannot be told "
            "from a signal"
        )
    for name, why in summary.get("figures_left_out", {}).items():
        lines.append(f"left out {name}: {why}")
    for direction, text in summary.get("output_peak", {}).items():
        lines.append(
            f"f_out: {text.replace('far-end output peak f_out', 'far-end output peak')}"
            + (f" [{direction}]" if len(summary["output_peak"]) > 1 else "")
        )
    return "\n".join(lines)


def write_summary(summary: dict[str, Any], path: str | Path) -> Path:
    """Write the summary as JSON; returns the path."""
    p = Path(path)
    p.write_text(json.dumps(summary, indent=2, allow_nan=False, default=_default) + "\n")
    return p


def _default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")
