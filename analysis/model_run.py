"""The model run on exactly what a run did: its bursts, drives, cylinders, window and range.

:func:`run_setup` reads from a run file everything the chain was subjected to:

* each direction's burst (centre frequency, cycles or width: the scan's attributes);
* each amplitude turned into what reached the chain: a protocol amplitude in metres was sent as
  generator volts through the bench's calibration (``Vpp = 2 a / (gain * stroke)``), so with the
  bench's own stroke the chain saw ``a``; with another stroke (``piezo_stroke_m_per_V``, e.g. a
  fitted one) it saw ``a * stroke / bench stroke``. A generator amplitude (``V``, peak-to-peak)
  reaches the chain as ``Vpp / 2 * gain * stroke``. Files without a bench (``biafc simulate``)
  hold the drive itself (m or N);
* the cylinders, time axis and sample rate of the scan;
* the vibrometer's clipping level (m/s): the decoder range's sensitivity (as read back at the
  start, else the bench's range) times the smaller of the decoder's full scale and the
  digitiser's input range.

:func:`predict` runs the model on that setup (the batched DEM, or the linear-response solver)
and returns the velocity ``[A, C, S]`` per direction on the run's own time axis, clipped like
the vibrometer; :func:`predicted_run` is the run file as the model would have written it, so
every analysis (maps, sweeps, transmission) applies to both unchanged.

:func:`chain_spec_of_run` is the model's view of the chain when no chain file is given: the
lengths, diameter and preload stored in the file's ``/chain``, the rest from the default chain.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from typing import Any, Literal, cast

import numpy as np
from numpy.typing import NDArray

from instruments.burst import Burst
from protocols.runfile import PointState, RunData, ScanData
from sim_backend.dem import ChainSpec, Drive, build_chain, default_chain_spec, simulate
from sim_backend.dem.chain import Chain
from sim_backend.dem.linear_response import linear_response

__all__ = [
    "DEFAULT_FULL_SCALE_V",
    "DirectionSetup",
    "RunSetup",
    "chain_spec_of_run",
    "predict",
    "predicted_run",
    "resonator_damping",
    "run_setup",
    "with_resonator_damping",
]

#: decoder analog full scale (V) when the file does not say (OFV-5000: +/-10 V)
DEFAULT_FULL_SCALE_V = 10.0


@dataclass(frozen=True)
class DirectionSetup:
    """What one direction of the run did to the chain.

    burst: the burst shape; drive_SI [A]: peak drive that reached the chain (m or N, ``kind``);
    cylinders [C] 1-based; time_s [S]; sample_rate_Hz.
    """

    direction: Literal["ltr", "rtl"]
    burst: Burst
    kind: Literal["displacement", "force"]
    drive_SI: NDArray[np.float64]
    cylinders: NDArray[np.int32]
    time_s: NDArray[np.float64]
    sample_rate_Hz: float


@dataclass(frozen=True)
class RunSetup:
    """Every direction's :class:`DirectionSetup`, the vibrometer clip level (m/s, ``inf`` when
    unknown) and where the drive calibration came from (``gain`` V/V, ``stroke`` m/V of the
    bench and the stroke used; ``None`` when the file holds the drive itself)."""

    directions: dict[str, DirectionSetup]
    clip_m_per_s: float
    amplifier_gain_V_per_V: float | None
    bench_stroke_m_per_V: float | None
    stroke_m_per_V: float | None

    @property
    def stroke_factor(self) -> float:
        """Stroke used over the bench's (1 when the file holds the drive itself)."""
        if self.stroke_m_per_V is None or self.bench_stroke_m_per_V is None:
            return 1.0
        return self.stroke_m_per_V / self.bench_stroke_m_per_V

    def with_stroke(self, stroke_m_per_V: float) -> RunSetup:
        """The same setup with another piezo stroke (drives rescaled)."""
        if self.bench_stroke_m_per_V is None or self.stroke_m_per_V is None:
            raise ValueError("this run file holds the drive itself: no piezo stroke to change")
        f = stroke_m_per_V / self.stroke_m_per_V
        dirs = {
            d: dataclasses.replace(s, drive_SI=s.drive_SI * f) for d, s in self.directions.items()
        }
        return dataclasses.replace(self, directions=dirs, stroke_m_per_V=stroke_m_per_V)


def _bench(run: RunData) -> Any:
    text = str(run.attrs.get("bench_yaml", "") or "")
    if not text.strip():
        return None
    from protocols.bench import parse_bench

    return parse_bench(text, f"{run.path}:/bench_yaml").bench


def _sensitivity(run: RunData, bench: Any) -> float | None:
    vib = run.snapshot.get("read_back", {}).get("vibrometer", {})
    sens = vib.get("sensitivity_m_per_s_per_V") if isinstance(vib, dict) else None
    if isinstance(sens, int | float) and sens > 0:
        return float(sens)
    if bench is not None:
        from instruments.polytec import parse_sensitivity

        try:
            return float(parse_sensitivity(bench.vibrometer.range))
        except Exception:
            return None
    return None


def run_setup(run: RunData, piezo_stroke_m_per_V: float | None = None) -> RunSetup:
    """What the run did (see the module docstring); ``piezo_stroke_m_per_V`` replaces the
    bench's stroke (a ValueError for a file without a bench: it holds the drive itself, and a
    stroke given for it was silently ignored)."""
    bench = _bench(run)
    if bench is None and piezo_stroke_m_per_V is not None:
        raise ValueError(
            "no bench in the file (it holds the drive itself, as biafc simulate writes it): a "
            "piezo stroke does not apply; drop --piezo-stroke"
        )
    gain = stroke = used = None
    kind: Literal["displacement", "force"] = "displacement"
    if bench is not None:
        gain = float(bench.amplifier.gain)
        kind = cast(Literal["displacement", "force"], bench.amplifier.kind)
        stroke = float(
            bench.amplifier.piezo_stroke
            if kind == "displacement"
            else (bench.amplifier.force_per_volt or float("nan"))
        )
        used = stroke if piezo_stroke_m_per_V is None else float(piezo_stroke_m_per_V)
    dirs: dict[str, DirectionSetup] = {}
    for d, scan in run.scans.items():
        units = scan.amplitude_units
        amps = np.asarray(scan.amplitudes, dtype=np.float64)
        if gain is None or stroke is None or used is None:
            if units not in ("m", "N"):
                raise ValueError(
                    f"{run.path}: scan/{d}/amplitudes in {units!r} and no bench in the file: "
                    "cannot tell what reached the chain"
                )
            drive = amps
            dkind: Literal["displacement", "force"] = "displacement" if units == "m" else "force"
        elif units == "V":
            drive = 0.5 * amps * gain * used
            dkind = kind
        elif units == "m":
            drive = amps * (used / stroke)
            dkind = "displacement"
        else:
            raise ValueError(f"{run.path}: scan/{d}/amplitudes: unknown units {units!r}")
        burst = Burst(
            scan.f_center_Hz,
            cycles=scan.cycles if scan.width_s is None else None,
            width_s=scan.width_s,
        )
        dirs[d] = DirectionSetup(
            direction=cast(Literal["ltr", "rtl"], d),
            burst=burst,
            kind=dkind,
            drive_SI=drive,
            cylinders=np.asarray(scan.cylinders, dtype=np.int32),
            time_s=np.asarray(scan.time_s, dtype=np.float64),
            sample_rate_Hz=scan.sample_rate_Hz,
        )
    sens = _sensitivity(run, bench)
    clip = math.inf
    if sens is not None:
        fs = DEFAULT_FULL_SCALE_V
        if bench is not None:
            if bench.simulation is not None:
                fs = float(bench.simulation.vibrometer_full_scale)
            fs = min(fs, float(bench.daq.velocity_range))
        clip = sens * fs
    return RunSetup(dirs, clip, gain, stroke, used)


def resonator_damping(spec: ChainSpec) -> float:
    """The modal damping ratio of ``spec``'s free-free bending modes (the chain file's
    ``damping.bending_mode_ratio``; the one place that names the field)."""
    return float(spec.damping.bending_mode_ratio)


def with_resonator_damping(spec: ChainSpec, ratio: float) -> ChainSpec:
    """``spec`` with the bending modes' damping ratio ``ratio`` (``bending_mode_ratio``)."""
    return spec.model_copy(
        update={"damping": spec.damping.model_copy(update={"bending_mode_ratio": float(ratio)})}
    )


def chain_spec_of_run(run: RunData) -> ChainSpec:
    """The chain as the run file's ``/chain`` records it (lengths, diameter, preload); every
    other setting from the default chain."""
    base = default_chain_spec()
    return base.model_copy(
        update={
            "n_cylinders": None,
            "length_first": None,
            "length_last": None,
            "lengths": tuple(float(x) for x in run.chain.lengths_m),
            "diameter": float(run.chain.diameter_m),
            "preload": float(run.chain.f0_N),
        }
    )


def model_duration_s(t_end_s: float, rate_Hz: float) -> float:
    """The model's run length (s) whose samples at ``rate_Hz`` (S/s) reach a record's last time
    ``t_end_s``: the models sample ``[0, duration]`` inclusive, and a duration of exactly
    ``t_end`` could round one sample short (its last value then read 0); at least 2 samples."""
    return max(t_end_s + 0.5 / rate_Hz, 2.0 / rate_Hz)


def _on_time_axis(
    model_t: NDArray[np.float64], v: NDArray[np.float64], t: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``v [..., S_model]`` sampled at ``model_t`` (from 0) onto the run's ``t`` (0 before)."""
    rate = 1.0 / (model_t[1] - model_t[0])
    k = np.round(t * rate)
    if np.allclose(k / rate, t, rtol=0, atol=1e-3 / rate):
        out = np.zeros(v.shape[:-1] + t.shape)
        idx = k.astype(np.int64)
        ok = (idx >= 0) & (idx < model_t.size)
        out[..., ok] = v[..., idx[ok]]
        return out
    flat = v.reshape(-1, v.shape[-1])
    res = np.stack([np.interp(t, model_t, row, left=0.0, right=0.0) for row in flat])
    return res.reshape(v.shape[:-1] + t.shape)


def predict(
    setup: RunSetup,
    chain: Chain,
    *,
    solver: Literal["dem", "linear"] = "dem",
    directions: tuple[str, ...] | None = None,
    clip: bool = True,
) -> dict[str, NDArray[np.float64]]:
    """The model's velocity ``[A, C, S]`` (m/s) per direction on the run's time axis.

    ``solver="dem"``: every amplitude of every direction in one batched DEM run;
    ``"linear"``: the linearised chain's exact response (one solution per burst shape, scaled).
    With ``clip`` the prediction is clipped at the vibrometer's level, like a measurement.
    """
    names = tuple(setup.directions) if directions is None else directions
    drives: list[Drive] = []
    owners: list[tuple[str, int]] = []
    t_end = 0.0
    rate = 0.0
    cyl: set[int] = set()
    for d in names:
        s = setup.directions[d]
        for a, amp in enumerate(s.drive_SI):
            drives.append(Drive(s.direction, s.kind, float(amp), s.burst))
            owners.append((d, a))
        t_end = max(t_end, float(s.time_s[-1]))
        rate = max(rate, s.sample_rate_Hz)
        cyl.update(int(c) for c in s.cylinders)
    if not drives:
        return {}
    cylinders = sorted(cyl)
    duration = model_duration_s(t_end, rate)
    if solver == "dem":
        res = simulate(
            chain,
            drives,
            duration_s=duration,
            sample_rate_Hz=rate,
            cylinders=cylinders,
            record=("velocity",),
        )
        vel, model_t = res.velocity, res.time_s
    else:
        lres = linear_response(
            chain,
            drives,
            duration_s=duration,
            sample_rate_Hz=rate,
            cylinders=cylinders,
            record=("velocity",),
        )
        assert lres.velocity is not None
        vel, model_t = lres.velocity, lres.time_s
    col = {c: i for i, c in enumerate(cylinders)}
    out: dict[str, NDArray[np.float64]] = {}
    for d in names:
        s = setup.directions[d]
        rows = [r for r, (dd, _) in enumerate(owners) if dd == d]
        cols = [col[int(c)] for c in s.cylinders]
        v = _on_time_axis(model_t, vel[np.ix_(rows, cols)], s.time_s)
        if clip and math.isfinite(setup.clip_m_per_s):
            v = np.clip(v, -setup.clip_m_per_s, setup.clip_m_per_s)
        out[d] = v
    return out


def predicted_run(run: RunData, prediction: dict[str, NDArray[np.float64]]) -> RunData:
    """``run`` with each direction's velocity replaced by the prediction, every point done,
    and the drive left as measured (so the input frequency is read the same way)."""
    scans: dict[str, ScanData] = {}
    for d, scan in run.scans.items():
        v = prediction.get(d)
        if v is None:
            continue
        scans[d] = dataclasses.replace(
            scan,
            velocity=v.astype(np.float32),
            done=np.full_like(scan.done, PointState.DONE),
        )
    attrs = dict(run.attrs)
    attrs["backend"] = "dem"
    attrs["status"] = "complete"
    attrs["model_of"] = json.dumps(str(run.path))
    return dataclasses.replace(run, scans=scans, attrs=attrs)


def chain_for(spec: ChainSpec | None, run: RunData) -> Chain:
    """The built chain of ``spec`` (default: :func:`chain_spec_of_run`)."""
    return build_chain(spec if spec is not None else chain_spec_of_run(run))
