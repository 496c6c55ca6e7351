"""Preflight of a connected bench (``biafc check``): what each instrument says about itself,
against what the bench file expects; optionally one low-amplitude burst through the whole chain.

:func:`check_settings` only reads (identity, firmware, settings, travel, error queue): nothing
moves and no output is switched. :func:`check_burst` homes the stage, goes to one cylinder,
fires one burst and reports the signal level, the velocity seen and the carrier measured on the
drive reference. Each result is a :class:`Finding`; a ``MISMATCH`` says what to check.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from daq.engine.instruments import BenchInstruments
from instruments.errors import ReplyError
from instruments.keysight import supported_model
from instruments.polytec import LevelAboveFullScale
from protocols.bench import BenchFile

__all__ = [
    "BurstTest",
    "Finding",
    "check_burst",
    "check_settings",
    "measured_carrier_Hz",
    "phase_slope_Hz",
]

Status = Literal["ok", "MISMATCH", "info"]

#: a carrier measured on the drive reference further than this (relative) from the burst's
#: is a mismatch (the generator must play it within 2e-4; the rest allows for the estimate on
#: one low-amplitude burst)
CARRIER_TOLERANCE = 5e-4


@dataclass(frozen=True)
class Finding:
    """One line of the preflight: ``expected`` is the bench file's value ("" where the bench
    file has no say), ``found`` the instrument's, ``hint`` what to do on a mismatch."""

    instrument: str
    item: str
    expected: str
    found: str
    status: Status
    hint: str = ""


def _mm(x_m: float) -> str:
    return f"{x_m * 1e3:.4g} mm"


def _attempt(
    out: list[Finding], instrument: str, item: str, fn: Callable[[], list[Finding]]
) -> None:
    """Run one group of checks; an instrument that fails to answer is itself a mismatch."""
    try:
        out.extend(fn())
    except Exception as exc:
        out.append(
            Finding(
                instrument,
                item,
                "",
                f"{type(exc).__name__}: {exc}".splitlines()[0],
                "MISMATCH",
                "the instrument did not answer: check it is on and connected",
            )
        )


# --- settings (read only) -------------------------------------------------------------------
def _generator(bf: BenchFile, gen: Any) -> list[Finding]:
    b = bf.bench
    out: list[Finding] = []
    idn = [p.strip() for p in gen.identify().split(",")]
    maker, model, serial, firmware = (idn + ["?"] * 4)[:4]
    ok_model = supported_model(model)  # the driver's own rule (its connect refuses the others)
    out.append(
        Finding(
            "generator",
            "identity",
            "Keysight 33500B/33600A",
            f"{maker} {model} s/n {serial}",
            "ok" if ok_model else "MISMATCH",
            ""
            if ok_model
            else "the driver speaks to a Keysight 33500B/33600A: check generator.resource",
        )
    )
    out.append(Finding("generator", "firmware", "", firmware, "info"))
    # what the queue held when the bench connected (said, not a mismatch: the connect cleared
    # them, and a second check would pass), then what it holds now
    before = list(getattr(gen, "errors_at_connect", []))
    if before:
        out.append(
            Finding(
                "generator",
                "errors before connecting",
                "",
                "; ".join(before) + " (cleared at connect)",
                "info",
                "left by an earlier session",
            )
        )
    errors = gen.errors()
    out.append(
        Finding(
            "generator",
            "error queue",
            "empty",
            "; ".join(errors) or "empty",
            "MISMATCH" if errors else "ok",
            "errors left from before: read them on the front panel, then clear them",
        )
    )
    for direction, ch in sorted(b.direction_channel.items(), key=lambda kv: kv[1]):
        on = bool(gen.output_state(ch))
        out.append(
            Finding(
                "generator",
                f"output {ch} ({direction})",
                "off",
                "ON" if on else "off",
                "MISMATCH" if on else "ok",
                "an output is on before the run: switch it off (biafc check never does)",
            )
        )
        load = _load_ohm(gen, ch)
        out.append(
            Finding(
                "generator",
                f"output {ch} load",
                "",
                _load_text(load),
                "info",
                "set to high Z (INF) with each burst: the amplifier input is high impedance",
            )
        )
    lim = gen.limits
    max_vpp = min(b.generator.max_amplitude, 2.0 * b.amplifier.piezo_max / b.amplifier.gain)
    same = (
        math.isclose(lim.max_amplitude_Vpp, b.generator.max_amplitude)
        and math.isclose(lim.amplifier_gain, b.amplifier.gain)
        and math.isclose(lim.max_piezo_V, b.amplifier.piezo_max)
    )
    out.append(
        Finding(
            "generator",
            "limits",
            f"{b.generator.max_amplitude:g} Vpp, gain {b.amplifier.gain:g}, piezo "
            f"{b.amplifier.piezo_max:g} V",
            f"{lim.max_amplitude_Vpp:g} Vpp, gain {lim.amplifier_gain:g}, piezo "
            f"{lim.max_piezo_V:g} V: at most {max_vpp:.4g} Vpp",
            "ok" if same else "MISMATCH",
            "the driver's limits are not the bench file's",
        )
    )
    return out


def _load_ohm(gen: Any, channel: int) -> float:
    """The output's load setting (ohm; inf for high Z), read back with ``OUTPn:LOAD?``."""
    return float(gen.transport.query(f"OUTP{channel}:LOAD?"))


def _load_text(load_ohm: float) -> str:
    return "high Z (INF)" if load_ohm > 1e30 else f"{load_ohm:g} ohm"


def _vibrometer(bf: BenchFile, vib: Any) -> list[Finding]:
    b = bf.bench
    out = [Finding("vibrometer", "identity", "Polytec OFV-5000", vib.identify(), "info")]
    rng = vib.velocity_range()
    same = rng.replace(" ", "").lower() == b.vibrometer.range.replace(" ", "").lower()
    out.append(
        Finding(
            "vibrometer",
            "velocity range",
            b.vibrometer.range,
            rng,
            "ok" if same else "MISMATCH",
            "the controller is on another range than the bench file: velocities would be "
            "scaled wrongly; set it on the controller or fix vibrometer.range",
        )
    )
    out.append(
        Finding(
            "vibrometer",
            "sensitivity",
            "",
            f"{vib.sensitivity_m_per_s_per_V() * 1e3:g} mm/s/V",
            "info",
        )
    )
    try:
        level = float(vib.signal_level())
    except ReplyError as exc:  # the findings above stand
        if isinstance(exc, LevelAboveFullScale):
            expected = f"level_full_scale {b.vibrometer.level_full_scale:g}"
            got = f"signal level {exc.reading} is above the full scale {exc.full_scale:g}"
            hint = "set vibrometer.level_full_scale to this controller's full scale"
        else:
            expected, got = "a number", str(exc).splitlines()[0]
            hint = "check the signal-level command (vibrometer: commands: signal_level_get)"
        out.append(Finding("vibrometer", "signal level here", expected, got, "MISMATCH", hint))
        return out
    out.append(
        Finding(
            "vibrometer",
            "signal level here",
            f">= {b.vibrometer.min_signal_level:g}",
            f"{level:.2f}",
            "info",
        )
    )
    return out


def _stage(bf: BenchFile, stage: Any) -> list[Finding]:
    b = bf.bench
    ident = stage.identity()  # read from the device at connect (id, resolution, limits)
    step = float(ident["microstep_m"])
    lo, hi = (float(v) for v in ident["travel_m"])
    named = b.stage.model or "-"
    out = [
        Finding(
            "stage",
            "model",
            named,
            f"device id {ident['device_id']}"
            + (f", firmware {ident['firmware']}" if ident.get("firmware") else ""),
            "ok",
        ),
        Finding(
            "stage",
            "microstep",
            f"{b.stage.microstep * 1e6:.6g} um" if b.stage.microstep else f"{named}'s",
            f"{step * 1e6:.6g} um at resolution {ident['resolution']}",
            "ok",
        ),
        Finding("stage", "travel", "", f"{_mm(lo)} .. {_mm(hi)}", "info"),
    ]
    soft_lo, soft_hi = b.stage.soft_limits
    inside = lo <= soft_lo and soft_hi <= hi
    out.append(
        Finding(
            "stage",
            "soft limits",
            f"{_mm(soft_lo)} .. {_mm(soft_hi)}",
            f"within travel {_mm(lo)} .. {_mm(hi)}" if inside else "outside the travel",
            "ok" if inside else "MISMATCH",
            "stage.soft_limits reach beyond the stage's travel: check the stage model",
        )
    )
    pos = b.positions_m()
    outside = [i + 1 for i, p in enumerate(pos) if not lo <= p <= hi]
    out.append(
        Finding(
            "stage",
            "cylinder positions",
            f"{len(pos)} cylinders {_mm(float(pos.min()))} .. {_mm(float(pos.max()))}",
            "all within travel"
            if not outside
            else f"cylinders {outside[0]}..{outside[-1]} ({len(outside)}) beyond the travel",
            "MISMATCH" if outside else "ok",
            "cylinder_positions do not fit this stage: check them and the stage model",
        )
    )
    out.append(Finding("stage", "homed", "", "yes" if stage.is_homed() else "no", "info"))
    out.append(Finding("stage", "position", "", _mm(float(stage.position())), "info"))
    return out


def _digitiser(bf: BenchFile, dig: Any) -> list[Finding]:
    d = bf.bench.daq
    snap = dig.snapshot()
    out = [
        Finding(
            "digitiser",
            "device",
            d.device,
            f"{snap.get('device')} ({snap.get('model', snap.get('kind', '?'))})",
            "ok" if snap.get("device") == d.device else "MISMATCH",
            "daq.device is not the device that answered",
        ),
    ]
    term = str(snap.get("terminal_config", "not reported"))
    out.append(
        Finding(
            "digitiser",
            "terminal configuration",
            d.terminal_config,
            term,
            "ok" if term == d.terminal_config else "MISMATCH",
            "the inputs are not wired as the bench file says: set daq.terminal_config",
        )
    )
    device_max = getattr(dig, "device_max_rate_per_channel_Hz", None)
    ceiling = float(device_max()) if device_max is not None else float(snap.get("max_rate_Hz", 0))
    fits = d.max_rate <= ceiling * (1 + 1e-9)
    out.append(
        Finding(
            "digitiser",
            "rate per channel",
            f"<= {d.max_rate:g} S/s",
            f"device: {ceiling:g} S/s on 2 channels",
            "ok" if fits else "MISMATCH",
            "daq.max_rate is above what the device does on two channels: lower it",
        )
    )
    out.append(
        Finding(
            "digitiser",
            "channels",
            "",
            f"{d.velocity_channel} velocity, {d.reference_channel} drive, trigger {d.trigger}",
            "info",
        )
    )
    return out


def check_settings(bf: BenchFile, inst: BenchInstruments) -> list[Finding]:
    """Every instrument's identity and settings against the bench file; reads only."""
    out: list[Finding] = []
    _attempt(out, "generator", "identity", lambda: _generator(bf, inst.generator))
    _attempt(out, "vibrometer", "identity", lambda: _vibrometer(bf, inst.vibrometer))
    _attempt(out, "stage", "travel", lambda: _stage(bf, inst.stage))
    _attempt(out, "digitiser", "device", lambda: _digitiser(bf, inst.digitiser))
    return out


# --- one burst (moves) ----------------------------------------------------------------------
def phase_slope_Hz(x: NDArray[np.float64], rate_Hz: float) -> float:
    """The mean frequency (Hz) of a narrowband signal ``x``: the slope of its analytic
    signal's phase where the envelope is above half its peak (weighted by the envelope)."""
    from analysis.envelope import analytic_signal

    x = np.asarray(x, dtype=np.float64)
    z = analytic_signal(x - float(np.median(x)))
    env = np.abs(z)
    keep = env >= 0.5 * float(np.max(env))
    if np.count_nonzero(keep) < 3:
        return math.nan
    t = np.arange(x.size)[keep] / rate_Hz
    slope = np.polyfit(t, np.unwrap(np.angle(z))[keep], 1, w=env[keep])[0]
    return float(slope) / (2.0 * math.pi)


def measured_carrier_Hz(x: NDArray[np.float64], rate_Hz: float, shape: Any) -> float:
    """The carrier (Hz) at which the burst ``shape`` (an ``instruments.burst.Burst``) was
    played in the record ``x`` (sampled at ``rate_Hz``): a least-squares fit of the burst
    stretched in time, ``a * shape((t - ts) * f / f_c) + c``, started from the phase slope.
    A generator playing its points at another rate stretches envelope and carrier alike."""
    from scipy.optimize import curve_fit

    x = np.asarray(x, dtype=np.float64)
    f_c = float(shape.f_center_Hz)
    t = np.arange(x.size) / rate_Hz
    c0 = float(np.median(x))
    f0 = phase_slope_Hz(x, rate_Hz)
    if not math.isfinite(f0) or f0 <= 0:
        return math.nan
    k = int(np.argmax(np.abs(x - c0)))
    # the burst peaks at the middle of its window: start near the largest sample
    ts0 = float(t[k]) - 0.5 * shape.duration_s * f_c / f0

    def model(tt: NDArray[np.float64], a: float, ts: float, f: float, c: float) -> Any:
        return a * shape.at((tt - ts) * f / f_c) + c

    best = math.nan
    best_cost = math.inf
    for half_periods in (-1, 0, 1):  # the largest sample may sit a half period off the centre
        p0 = [float(x[k] - c0) * (-1) ** abs(half_periods), ts0 + half_periods * 0.5 / f0, f0, c0]
        try:
            popt, _ = curve_fit(model, t, x, p0=p0, maxfev=4000)
        except (RuntimeError, ValueError):
            continue
        cost = float(np.sum((model(t, *popt) - x) ** 2))
        if cost < best_cost:
            best, best_cost = float(popt[2]), cost
    return best


@dataclass(frozen=True)
class BurstTest:
    """What the burst of ``--move`` is: direction, cylinder, carrier (Hz), cycles, Vpp."""

    direction: str = "ltr"
    cylinder: int = 1
    f_center_Hz: float = 8.92e3
    cycles: float = 5.0
    amplitude_Vpp: float = 0.2
    record_s: float = 10e-3
    rate_Hz: float = 200e3


#: the item of the finding :func:`safe_state_finding` makes
SAFE_STATE_ITEM = "safe state after the burst"


def safe_state_finding(bf: BenchFile, inst: BenchInstruments) -> tuple[Finding, bool]:
    """After the burst test: every instrument to its safe state, the generator's outputs read
    back and the stage asked whether its axis came to rest (the run's own path,
    :mod:`daq.engine.safe_state`). Returns the finding and whether the bench is *unsafe*
    (something not confirmed off: the finding's hint says what to switch off by hand); a
    problem on the way (a stage that did not answer) is a MISMATCH that is not unsafe."""
    from daq.engine.outcome import unsafe_instruction
    from daq.engine.safe_state import bring_to_safe_state

    channels = sorted(set(bf.bench.direction_channel.values()))
    expected = "outputs off, stage at rest"
    try:
        found = bring_to_safe_state(inst, channels)
    except Exception as exc:  # never raises by design; said, not lost, if it does
        text = f"{type(exc).__name__}: {exc}".splitlines()[0]
        return Finding("bench", SAFE_STATE_ITEM, expected, text, "MISMATCH", "not confirmed"), True
    if found.unconfirmed:
        text = "; ".join(found.unconfirmed + found.problems)
        hint = unsafe_instruction(found.unconfirmed)
        return Finding("bench", SAFE_STATE_ITEM, expected, text, "MISMATCH", hint), True
    if found.problems:
        text = "outputs confirmed off; " + "; ".join(found.problems)
        hint = "check the instrument's cable and power"
        return Finding("bench", SAFE_STATE_ITEM, expected, text, "MISMATCH", hint), False
    return Finding("bench", SAFE_STATE_ITEM, expected, "confirmed", "ok"), False


def burst_peak_factor(bf: BenchFile, test: BurstTest) -> float:
    """The test burst's ``arb_peak_factor`` at the bench's generator rate (the piezo limit is
    checked with it, as the driver checks the burst it uploads)."""
    from instruments.burst import Burst, burst_samples
    from instruments.keysight import arb_peak_factor

    shape = Burst(test.f_center_Hz, cycles=test.cycles)
    return arb_peak_factor(burst_samples(shape, bf.bench.generator.sample_rate))


def check_burst(bf: BenchFile, inst: BenchInstruments, test: BurstTest) -> list[Finding]:
    """Home, go to ``test.cylinder``, fire one burst; signal level, velocity and carrier.
    The caller brings the bench to its safe state and confirms it (:func:`safe_state_finding`),
    also when this raises: ``biafc check`` does, in a ``finally``."""
    from instruments.burst import Burst
    from instruments.interfaces import AcquisitionConfig, BurstConfig

    b = bf.bench
    out: list[Finding] = []
    if not 1 <= test.cylinder <= b.n_cylinders:
        raise ValueError(f"cylinder {test.cylinder} is not one of 1..{b.n_cylinders}")
    why = b.amplitude_limit_error(test.amplitude_Vpp, burst_peak_factor(bf, test))
    if why is not None:
        raise ValueError(why)
    channel = b.direction_channel[test.direction]  # type: ignore[index]
    gen, vib, stage, dig = inst.generator, inst.vibrometer, inst.stage, inst.digitiser
    stage.home()
    stage.move_to(float(b.positions_m()[test.cylinder - 1]))
    inst.wait(b.stage.settle, threading.Event())  # never set: the wait runs to its end
    level = float(vib.signal_level())
    good = level >= b.vibrometer.min_signal_level
    out.append(
        Finding(
            "burst",
            f"signal level at cylinder {test.cylinder}",
            f">= {b.vibrometer.min_signal_level:g}",
            f"{level:.2f}",
            "ok" if good else "MISMATCH",
            "the laser does not see the cylinder: check its position and the focus",
        )
    )
    rate = min(test.rate_Hz, b.daq.max_rate)
    n_pre = 100
    n = n_pre + round(test.record_s * rate)
    rate = dig.configure(
        AcquisitionConfig(
            sample_rate_Hz=rate,
            n_samples=n,
            n_pretrigger=n_pre,
            velocity_channel=b.daq.velocity_channel,
            reference_channel=b.daq.reference_channel,
            velocity_range_V=b.daq.velocity_range,
            reference_range_V=b.daq.reference_range,
            trigger_source=b.daq.trigger,
            timeout_s=2.0,
        )
    )
    shape = Burst(test.f_center_Hz, cycles=test.cycles)
    gen.configure_burst(
        channel,
        BurstConfig(
            shape=shape,
            amplitude_Vpp=test.amplitude_Vpp,
            sample_rate_Hz=b.generator.sample_rate,
        ),
    )
    load = _load_ohm(gen, channel)
    high_z = load > 1e30
    out.append(
        Finding(
            "burst",
            f"output {channel} load",
            "high Z (INF)",
            _load_text(load),
            "ok" if high_z else "MISMATCH",
            "the amplifier input is high impedance: with another load setting the "
            "piezo sees another voltage than the one asked for",
        )
    )
    if not high_z:
        raise ValueError(f"output {channel} load is {_load_text(load)}, not high Z")
    gen.output(channel, True)
    dig.arm()
    gen.trigger()
    rec = dig.read()
    sens = float(vib.sensitivity_m_per_s_per_V())
    v = np.asarray(rec.velocity_V, dtype=np.float64)
    d = np.asarray(rec.reference_V, dtype=np.float64)
    noise = float(np.std(v[:n_pre])) if n_pre > 1 else 0.0
    peak = float(np.max(np.abs(v[n_pre:])))
    seen = peak > 5.0 * noise and peak > 0
    out.append(
        Finding(
            "burst",
            "velocity peak",
            "",
            f"{peak * sens * 1e3:.4g} mm/s "
            f"({100 * peak / b.daq.velocity_range:.3g} % of the input range, "
            f"{peak / noise if noise else math.inf:.3g} x the noise)",
            "ok" if seen else "MISMATCH",
            "no response above the noise: check the piezo drive and the vibrometer cable",
        )
    )
    f_drive = measured_carrier_Hz(d, rate, shape)
    rel = abs(f_drive - test.f_center_Hz) / test.f_center_Hz
    out.append(
        Finding(
            "burst",
            "carrier on the drive reference",
            f"{test.f_center_Hz:.6g} Hz",
            f"{f_drive:.6g} Hz ({rel:.1e} off)",
            "ok" if rel <= CARRIER_TOLERANCE else "MISMATCH",
            "the drive is not at the burst's carrier: check the generator's "
            "sample rate and the reference cable",
        )
    )
    out.append(
        Finding(
            "burst",
            "carrier of the velocity",
            "",
            f"{phase_slope_Hz(v[n_pre:], rate):.6g} Hz",
            "info",
        )
    )
    return out
