"""Measurement beside model: residuals of a run against the model's prediction of the same run.

For every point of a run (direction ``d``, amplitude ``a``, cylinder ``c``) the measured
velocity ``v`` and the predicted ``p`` (:mod:`analysis.model_run`, same time axis and clipping)
give two relative residuals:

* time domain: ``r_t = ||v - p|| / ||v||`` (L2 over the record; sensitive to the trigger's
  timing and to phase);
* spectral: ``r_s = || |V| - |P| || / || |V| ||`` with ``|V|``, ``|P|`` the magnitude spectra in
  ``RESIDUAL_BAND_HZ`` (insensitive to a time shift; the shape and level of the response).

0 is a perfect prediction and 1 is as good as predicting nothing. Each point has a state:
``ok``, ``pending`` (not measured), ``failed`` (the engine gave up on it) or ``clipped`` (the
measured record reaches the vibrometer's clipping level: the model cannot be compared with
it). Only ``ok`` points enter the table: per cylinder the RMS over its points (both
directions, every amplitude), and one figure of merit, the RMS of ``r_s`` over every ``ok``
point (each point counts once, whatever its energy).

Noise. A far record at the noise floor (:attr:`analysis.sweep.AmplitudeSweep.at_noise_floor`:
no more energy in the band where the signal can be than its pre-trigger noise's there) holds
only an upper bound of the far end's signal: its residual is that of the noise (about 1 for a
perfect model), so it is counted (``n_noise_floor``) and left out of the table and the figure
of merit. Beside each residual its noise reference: the time-domain one
``sigma sqrt(S) / ||v||`` (:func:`noise_floor`) and the spectral one
``sqrt(E_noise / E)`` in ``RESIDUAL_BAND_HZ`` (:func:`spectral_noise_floor`), what the
measurement noise alone gives a perfect model (on the simulated bench compared with its own
chain, the figure of merit 0.198 against 0.199).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from analysis.noise_floor import MIN_BAND_DOF, band_dof, band_energy, band_noise_energy
from analysis.spectra import amplitude_spectrum
from analysis.sweep import AmplitudeSweep, amplitude_sweep
from analysis.transmission import signal_energy
from protocols.runfile import PointState, RunData

__all__ = [
    "CLIP_FRACTION",
    "RESIDUAL_BAND_HZ",
    "Comparison",
    "DirectionComparison",
    "compare_runs",
    "format_table",
    "point_states",
    "spectral_noise_floor",
]

#: band (Hz) of the spectral residual: every band of the default chain up to the third
RESIDUAL_BAND_HZ = (1.0e3, 20.0e3)
#: a measured record whose peak reaches this fraction of the clip level counts as clipped
CLIP_FRACTION = 0.995

#: pre-trigger samples needed to estimate the noise floor
MIN_PRETRIGGER = 20

STATES = ("ok", "pending", "failed", "clipped")
#: the state of a cylinder the run's protocol does not scan (no point of it, pending or not)
UNSCANNED = "unscanned"


def point_states(
    done: NDArray[np.uint8], velocity: NDArray[Any], clip_m_per_s: float
) -> NDArray[np.str_]:
    """``[A, C]`` state of every point (see the module docstring)."""
    state = np.full(done.shape, "pending", dtype="<U8")
    state[done == PointState.FAILED] = "failed"
    measured = done == PointState.DONE
    peak = np.nanmax(np.abs(np.where(np.isfinite(velocity), velocity, 0.0)), axis=-1)
    finite = np.all(np.isfinite(velocity), axis=-1)
    state[measured & finite] = "ok"
    state[measured & ~finite] = "failed"
    if math.isfinite(clip_m_per_s):
        state[measured & finite & (peak >= CLIP_FRACTION * clip_m_per_s)] = "clipped"
    return state


@dataclass(frozen=True)
class DirectionComparison:
    """One direction: ``state [A, C]``, ``time_residual [A, C]``, ``spectral_residual [A, C]``
    (NaN where the state is not ``ok``), their noise references ``noise_residual [A, C]`` and
    ``spectral_noise [A, C]``, ``at_noise_floor [A, C]`` (the far cylinder's ``ok`` points whose
    record is at the noise floor: not compared), the measured and predicted amplitude sweeps,
    and ``predicted_signal [A]``: the model's far-end signal over its E_entry as the measured
    ``signal_transmission`` is taken (its energy in the measured sweep's ``signal_band_Hz``
    where the measured noise is known, else the whole records'), the quantity to set beside
    the measured one and its bounds."""

    direction: str
    cylinders: NDArray[np.int32]
    state: NDArray[np.str_]
    time_residual: NDArray[np.float64]
    spectral_residual: NDArray[np.float64]
    noise_residual: NDArray[np.float64]
    measured_sweep: AmplitudeSweep
    predicted_sweep: AmplitudeSweep
    spectral_noise: NDArray[np.float64]
    at_noise_floor: NDArray[np.bool_]
    predicted_signal: NDArray[np.float64]

    def state_of(self, cylinder: int) -> NDArray[np.str_]:
        """``[A]`` state of cylinder ``cylinder`` (1-based); ``unscanned`` when it is not in the
        run's protocol (it was called ``pending``, "not measured yet", before)."""
        hits = np.nonzero(self.cylinders == cylinder)[0]
        if not hits.size:
            return np.full(self.state.shape[0], UNSCANNED, dtype="<U9")
        return self.state[:, hits[0]].astype("<U9")

    def sweep_state(self) -> NDArray[np.str_]:
        """``[A]`` the worse state of the entry and far points (what the sweep relies on)."""
        ms = self.measured_sweep
        entry, far = self.state_of(ms.entry), self.state_of(ms.far)
        out = far.copy()
        for st in ("pending", "clipped", "failed", UNSCANNED):
            out[(entry == st) | (far == st)] = st
        return out

    def far_scanned(self) -> bool:
        """Whether the far cylinder is in the run's protocol (its spectra can be compared)."""
        return bool(np.any(self.cylinders == self.measured_sweep.far))

    def sweep_scanned(self) -> bool:
        """Whether the entry and far cylinders are both in the run's protocol (the sweep's
        transmission and far-end peak can be compared)."""
        return self.far_scanned() and bool(np.any(self.cylinders == self.measured_sweep.entry))


@dataclass(frozen=True)
class Comparison:
    """A whole run against its prediction.

    cylinders [K] (1-based, every cylinder of any direction), per-cylinder RMS residuals
    ``time_residual [K]``, ``spectral_residual [K]`` and point counts ``n_points [K]``, and the
    figure of merit (RMS spectral residual over every ``ok`` point not at the noise floor; NaN
    when there is none), its noise reference ``spectral_noise_figure`` (the same RMS of what
    the noise alone gives a perfect model) and ``n_noise_floor``, the far records at the noise
    floor left out.
    """

    directions: dict[str, DirectionComparison]
    cylinders: NDArray[np.int32]
    time_residual: NDArray[np.float64]
    spectral_residual: NDArray[np.float64]
    noise_residual: NDArray[np.float64]
    n_points: NDArray[np.int64]
    figure_of_merit: float
    time_figure: float
    noise_figure: float
    counts: dict[str, int] = field(default_factory=dict)
    spectral_noise: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    spectral_noise_figure: float = math.nan
    n_noise_floor: int = 0

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary (residuals, counts, figure of merit)."""

        def num(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {
            "figure_of_merit": num(self.figure_of_merit),
            "figure_of_merit_meaning": "RMS over usable points of the relative spectral "
            f"residual || |V|-|P| || / || |V| || in {RESIDUAL_BAND_HZ[0]:g}-"
            f"{RESIDUAL_BAND_HZ[1]:g} Hz (0 perfect, 1 = predicting nothing); far records at "
            "the noise floor are left out",
            "figure_of_merit_noise_floor": num(self.spectral_noise_figure),
            "figure_of_merit_noise_floor_meaning": "the figure of merit the measurement noise "
            "alone would give a perfect model: RMS of sqrt(E_noise / E) in the same band "
            "(noise level from the pre-trigger samples)",
            "far_records_at_noise_floor": int(self.n_noise_floor),
            "far_records_at_noise_floor_meaning": "measured far records holding no more than "
            "their noise in the band where the signal can be: only an upper bound of the "
            "transmission; not compared (left out of the table and the figure of merit)",
            "time_residual_rms": num(self.time_figure),
            "noise_floor_rms": num(self.noise_figure),
            "noise_floor_meaning": "the time-domain residual the measurement noise alone would "
            "give a perfect model (noise RMS before the trigger)",
            "points": dict(self.counts),
            "cylinders": [
                {
                    "cylinder": int(c),
                    "points": int(n),
                    "spectral_residual": num(float(s)),
                    "time_residual": num(float(t)),
                    "noise_floor": num(float(f)),
                    "spectral_noise_floor": num(float(sn)),
                }
                for c, n, s, t, f, sn in zip(
                    self.cylinders,
                    self.n_points,
                    self.spectral_residual,
                    self.time_residual,
                    self.noise_residual,
                    self.spectral_noise_per_cylinder(),
                    strict=True,
                )
            ],
        }

    def spectral_noise_per_cylinder(self) -> NDArray[np.float64]:
        """``[K]`` per-cylinder spectral noise reference (NaN when not computed)."""
        sn = np.asarray(self.spectral_noise, dtype=np.float64)
        return sn if sn.shape == self.cylinders.shape else np.full(self.cylinders.shape, np.nan)


def _rms(arr: NDArray[np.float64]) -> NDArray[np.float64]:
    """RMS over rows of ``arr [P, K]``, ignoring NaN per column (NaN when a column has none)."""
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.sqrt(np.nanmean(arr**2, axis=0))


def noise_floor(velocity: NDArray[np.float64], time_s: NDArray[np.float64]) -> NDArray[np.float64]:
    """``[A, C]`` the time-domain residual that the measurement noise alone gives a perfect
    model: ``sigma sqrt(S) / ||v||`` with ``sigma`` the RMS before the trigger (NaN when the
    record has fewer than ``MIN_PRETRIGGER`` samples before it)."""
    pre = time_s < 0
    shape = velocity.shape[:-1]
    if np.count_nonzero(pre) < MIN_PRETRIGGER:
        return np.full(shape, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma = np.sqrt(np.mean(velocity[..., pre] ** 2, axis=-1))
        return np.asarray(
            sigma * math.sqrt(velocity.shape[-1]) / np.sqrt(np.sum(velocity**2, axis=-1)),
            dtype=np.float64,
        )


def spectral_noise_floor(
    velocity: NDArray[np.float64], time_s: NDArray[np.float64], sample_rate_Hz: float
) -> NDArray[np.float64]:
    """``[A, C]`` the spectral residual that the measurement noise alone gives a perfect model:
    ``sqrt(E_noise / E)`` within ``RESIDUAL_BAND_HZ``, ``E`` the record's energy there and
    ``E_noise`` the noise's, from the pre-trigger samples (NaN with fewer than
    ``MIN_PRETRIGGER`` of them). It is what the residual of a noise-only record comes to (1)
    and overstates a clean record's by up to sqrt(2) (only the noise in phase with the signal
    moves its magnitude), where the residual is small anyway."""
    pre = time_s < 0
    if (
        np.count_nonzero(pre) < MIN_PRETRIGGER
        or band_dof(time_s, sample_rate_Hz, RESIDUAL_BAND_HZ) < MIN_BAND_DOF
    ):  # too short a pre-trigger to know the noise within the band: no reference
        return np.full(velocity.shape[:-1], np.nan)
    e = band_energy(velocity, sample_rate_Hz, RESIDUAL_BAND_HZ)
    n = band_noise_energy(velocity, time_s, sample_rate_Hz, RESIDUAL_BAND_HZ)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(np.sqrt(n / e), dtype=np.float64)


def _predicted_signal(
    pred: NDArray[np.float64], ms: AmplitudeSweep, cylinders: NDArray[Any], rate: float
) -> NDArray[np.float64]:
    """``[A]`` the model's far-end signal over its E_entry, taken as ``ms.signal_transmission``
    is: within ``ms.signal_band_Hz`` where the measured far record's noise is known and not
    zero (its ``far_noise_ratio`` finite), else the whole records' (``pred [A, C, S]``)."""
    far = np.nonzero(cylinders == ms.far)[0]
    entry = np.nonzero(cylinders == ms.entry)[0]
    if not far.size or not entry.size:
        return np.full(len(ms.amplitudes), np.nan)
    v_far, v_entry = pred[:, far[0]], pred[:, entry[0]]
    e_entry = signal_energy(v_entry, rate)
    with np.errstate(divide="ignore", invalid="ignore"):
        band = band_energy(v_far, rate, ms.signal_band_Hz) / e_entry
        whole = signal_energy(v_far, rate) / e_entry
    return np.asarray(np.where(np.isfinite(ms.far_noise_ratio), band, whole), dtype=np.float64)


def _residuals(
    meas: NDArray[np.float64], pred: NDArray[np.float64], rate: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Time and spectral relative residuals of records ``[..., S]``."""
    num_t = np.sqrt(np.sum((meas - pred) ** 2, axis=-1))
    den_t = np.sqrt(np.sum(meas**2, axis=-1))
    sm = amplitude_spectrum(meas, rate).band(*RESIDUAL_BAND_HZ).magnitude
    sp = amplitude_spectrum(pred, rate).band(*RESIDUAL_BAND_HZ).magnitude
    num_s = np.sqrt(np.sum((sm - sp) ** 2, axis=-1))
    den_s = np.sqrt(np.sum(sm**2, axis=-1))
    with np.errstate(divide="ignore", invalid="ignore"):
        return num_t / den_t, num_s / den_s


def compare_runs(run: RunData, predicted: RunData, clip_m_per_s: float) -> Comparison:
    """Compare ``run`` with ``predicted`` (:func:`analysis.model_run.predicted_run`)."""
    dirs: dict[str, DirectionComparison] = {}
    per_cyl: dict[int, list[tuple[float, float, float, float]]] = {}
    counts = dict.fromkeys(STATES, 0)
    n_floor = 0
    for d, scan in run.scans.items():
        pscan = predicted.scans[d]
        vel = np.asarray(scan.velocity, dtype=np.float64)
        pvel = np.asarray(pscan.velocity, dtype=np.float64)
        state = point_states(scan.done, vel, clip_m_per_s)
        ok = state == "ok"
        t_res = np.full(state.shape, np.nan)
        s_res = np.full(state.shape, np.nan)
        n_res = noise_floor(vel, scan.time_s)
        n_res[~ok] = np.nan
        sn_res = spectral_noise_floor(vel, scan.time_s, scan.sample_rate_Hz)
        sn_res[~ok] = np.nan
        if np.any(ok):
            rt, rs = _residuals(vel[ok], pvel[ok], scan.sample_rate_Hz)
            t_res[ok], s_res[ok] = rt, rs
        # both against the band edges of the chain the prediction was made with
        ms = amplitude_sweep(scan, predicted.chain)
        # a far record at the noise floor bounds the signal; its residual is the noise's
        floor = np.zeros(state.shape, dtype=bool)
        i_far = np.nonzero(scan.cylinders == ms.far)[0]
        if i_far.size:
            floor[:, i_far[0]] = ms.at_noise_floor & ok[:, i_far[0]]
        n_floor += int(np.count_nonzero(floor))
        for name in STATES:
            counts[name] += int(np.count_nonzero(state == name))
        for a, c in zip(*np.nonzero(ok & ~floor), strict=True):
            per_cyl.setdefault(int(scan.cylinders[c]), []).append(
                (t_res[a, c], s_res[a, c], n_res[a, c], sn_res[a, c])
            )
        dirs[d] = DirectionComparison(
            direction=d,
            cylinders=np.asarray(scan.cylinders, dtype=np.int32),
            state=state,
            time_residual=t_res,
            spectral_residual=s_res,
            noise_residual=n_res,
            measured_sweep=ms,
            predicted_sweep=amplitude_sweep(pscan, predicted.chain),
            spectral_noise=sn_res,
            at_noise_floor=floor,
            predicted_signal=_predicted_signal(pvel, ms, scan.cylinders, scan.sample_rate_Hz),
        )
    all_cyl = sorted({int(c) for s in run.scans.values() for c in s.cylinders})
    t_c = np.full(len(all_cyl), np.nan)
    s_c = np.full(len(all_cyl), np.nan)
    f_c = np.full(len(all_cyl), np.nan)
    sn_c = np.full(len(all_cyl), np.nan)
    n_c = np.zeros(len(all_cyl), dtype=np.int64)
    everything: list[tuple[float, float, float, float]] = []
    for i, c in enumerate(all_cyl):
        pts = [p for p in per_cyl.get(c, []) if math.isfinite(p[0]) and math.isfinite(p[1])]
        n_c[i] = len(pts)
        if pts:
            arr = np.asarray(pts)
            t_c[i], s_c[i], f_c[i], sn_c[i] = _rms(arr)
            everything += pts
    fom = time_fom = noise_fom = spec_noise_fom = math.nan
    if everything:
        time_fom, fom, noise_fom, spec_noise_fom = (float(x) for x in _rms(np.asarray(everything)))
    return Comparison(
        directions=dirs,
        cylinders=np.asarray(all_cyl, dtype=np.int32),
        time_residual=t_c,
        spectral_residual=s_c,
        noise_residual=f_c,
        n_points=n_c,
        figure_of_merit=fom,
        time_figure=time_fom,
        noise_figure=noise_fom,
        counts=counts,
        spectral_noise=sn_c,
        spectral_noise_figure=spec_noise_fom,
        n_noise_floor=n_floor,
    )


def format_table(cmp: Comparison) -> str:
    """The per-cylinder residual table and the figure of merit, as printed text."""
    lines = ["cylinder  points  spectral residual (noise alone)  time residual  noise floor"]
    for c, n, s, sn, t, f in zip(
        cmp.cylinders,
        cmp.n_points,
        cmp.spectral_residual,
        cmp.spectral_noise_per_cylinder(),
        cmp.time_residual,
        cmp.noise_residual,
        strict=True,
    ):
        fs = f"{s:17.3f}" if math.isfinite(s) else f"{'-':>17}"
        fsn = f"({sn:.3f})" if math.isfinite(sn) else "(-)"
        ft = f"{t:13.3f}" if math.isfinite(t) else f"{'-':>13}"
        ff = f"{f:11.3f}" if math.isfinite(f) else f"{'-':>11}"
        lines.append(f"{c:8d}  {n:6d}  {fs} {fsn:>14}  {ft}  {ff}")
    c = cmp.counts
    nf = cmp.n_noise_floor
    lines.append(
        f"points: {c.get('ok', 0) - nf} compared, {nf} far record{'' if nf == 1 else 's'} at "
        f"the noise floor (upper bounds only), {c.get('clipped', 0)} clipped, "
        f"{c.get('failed', 0)} failed, {c.get('pending', 0)} not measured (marked, not compared)"
    )
    lines.append(
        "figure of merit (RMS spectral residual, 0 perfect, 1 = predicting nothing): "
        f"{_f(cmp.figure_of_merit)} (noise alone: {_f(cmp.spectral_noise_figure)}); "
        f"time-domain residual RMS: {_f(cmp.time_figure)} (noise floor {_f(cmp.noise_figure)})"
    )
    return "\n".join(lines)


def _f(x: float) -> str:
    return f"{x:.3f}" if math.isfinite(x) else "n/a"
