"""The simulated world: one DEM chain behind the emulated generator, vibrometer, stage and DAQ.

The coupling, in the order a measurement happens:

1. The generator emulator holds, per channel, the arbitrary waveform the driver uploaded
   (samples normalised to the DAC's full scale), its sample rate, amplitude and offset, and the
   output state. On a trigger (``*TRG``) every channel whose output is ON plays; the channel
   gives the direction (``direction_channel``) and the actuator model turns volts into the
   piezo's displacement (m) or force (N). Output OFF: nothing moves.
2. The stage emulator's position picks the cylinder the laser sees (nearest cylinder position
   within ``spot_tolerance_m``); between cylinders there is no velocity signal and the
   vibrometer reports a low signal level.
3. The armed digitiser latches the trigger; on ``read()`` the world fetches the DEM record for
   (direction, drive, waveform) from the cache (one run serves all cylinders and averages),
   delays it by the decoder delay, scales by the vibrometer range, clips at the decoder's full
   scale, adds decoder noise, digitiser noise, clipping and quantisation. The reference channel
   records the generator output (the drive voltage).
4. Time is simulated (:attr:`SimWorld.clock`): moves, settling, timeouts and records advance it;
   with ``speedup = 0`` nothing waits.

All randomness comes from ``seed`` and the acquisition counter, so a run is reproducible.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from instruments.errors import InstrumentError
from instruments.interfaces import AcquisitionConfig
from sim_backend.simbench.config import SimWorldConfig
from sim_backend.simbench.dem_cache import (
    DemKey,
    DemRunner,
    DemStats,
    Simulator,
    dem_simulator,
    waveform_digest,
)
from sim_backend.simbench.digitiser import SimDigitiser
from sim_backend.simbench.faults import FaultPlan
from sim_backend.simbench.signal_chain import decoder_output, digitise, on_grid

if TYPE_CHECKING:
    from sim_backend.emulators import SimClock
    from sim_backend.simbench.emulated import WorldTransport

__all__ = ["ChannelPlay", "SimWorld", "TriggerEvent"]

#: vibrometer signal level on a cylinder, between cylinders, and with the signal lost
LEVEL_ON_TARGET = 0.85
LEVEL_BETWEEN = 0.03
LEVEL_LOST = 0.0
#: decoder output noise (m/s rms) without an optical signal: the decoder outputs garbage
NO_SIGNAL_NOISE_FACTOR = 100.0


@dataclass(frozen=True)
class ChannelPlay:
    """What one generator channel plays on a trigger.

    Attributes
    ----------
    channel:
        1-based generator channel.
    samples:
        ``[n]`` waveform normalised to the DAC's full scale (-1..1).
    sample_rate_Hz:
        Arbitrary-waveform sample rate (Sa/s).
    amplitude_Vpp:
        Output amplitude, peak-to-peak V: full scale maps to +/- ``amplitude_Vpp / 2``.
    offset_V:
        DC offset (V).
    """

    channel: int
    samples: NDArray[np.float64]
    sample_rate_Hz: float
    amplitude_Vpp: float
    offset_V: float = 0.0

    def volts(self, t_s: NDArray[np.float64]) -> NDArray[np.float64]:
        """Output voltage at ``t_s`` (s from the trigger), ``[S]``; the offset outside the burst."""
        n = self.samples.shape[0]
        tw = np.arange(n) / self.sample_rate_Hz
        play = np.interp(t_s, tw, self.samples, left=0.0, right=0.0)
        return 0.5 * self.amplitude_Vpp * play + self.offset_V


@dataclass(frozen=True)
class TriggerEvent:
    """The world's state when a trigger fired: what played and where the laser was."""

    time_s: float
    plays: tuple[ChannelPlay, ...]
    stage_position_m: float
    range_name: str
    decoder_delay_s: float
    sensitivity_m_per_s_per_V: float
    signal_lost: bool
    meta: dict[str, Any] = field(default_factory=dict)


class SimWorld:
    """The simulated bench. See the module docstring for the coupling.

    Parameters
    ----------
    config:
        The world's settings.
    simulator:
        Replaces the DEM (tests only): ``(DemKey, normalised waveform) -> DemRecord``.
    """

    def __init__(self, config: SimWorldConfig | None = None, *, simulator: Simulator | None = None):
        self.config = config if config is not None else SimWorldConfig()
        cfg = self.config
        self.faults: FaultPlan = cfg.faults
        self._dem = DemRunner(
            simulator
            if simulator is not None
            else dem_simulator(cfg.chain_spec, cfg.dem_integrator, cfg.dem_dt_s),
            cache_size=cfg.dem_cache_size,
            cache_bytes=round(cfg.dem_cache_MB * 2**20),
        )
        self.n_acquisitions = 0
        self.n_triggers = 0
        self._stream_counts: dict[tuple[str, int], int] = {}
        self._armed: SimDigitiser | None = None
        self._latched: TriggerEvent | None = None
        self._positions_m: NDArray[np.float64] | None = (
            None
            if cfg.cylinder_positions_m is None
            else np.asarray(cfg.cylinder_positions_m, dtype=np.float64)
        )
        self._setup_instruments()

    # --- instrument side (emulators, transports, clock): see emulated.py ----------------------
    def _setup_instruments(self) -> None:
        from sim_backend.simbench import emulated

        self._inst = emulated.EmulatedInstruments(self)
        #: the simulated clock shared by the emulators, the drivers' polling and the digitiser
        self.clock: SimClock = self._inst.clock

    def transport(self, instrument: str, baud_rate: int | None = None) -> WorldTransport:
        """A Transport to the emulated ``"generator"``, ``"vibrometer"`` or ``"stage"``
        (``baud_rate``: the line speed of a serial one, as the bench file sets it)."""
        return self._inst.transport(instrument, baud_rate)

    def digitiser(self, device: str = "Dev1", terminal_config: str = "default") -> SimDigitiser:
        """The simulated digitiser (same interface as the NI-DAQmx one)."""
        return SimDigitiser(self, device=device, terminal_config=terminal_config)

    # --- geometry -------------------------------------------------------------------------------
    @property
    def cylinder_positions_m(self) -> NDArray[np.float64]:
        """``[N]`` stage position (m) of each cylinder's contact point, cylinder order."""
        if self._positions_m is None:
            n, pitch = self._chain_geometry()
            positions = self.config.first_cylinder_m + pitch * np.arange(n, dtype=np.float64)
            high = self.config.stage_travel_m[1]
            if positions[-1] > high:
                raise ValueError(
                    f"cylinder positions reach {positions[-1]:.4g} m, beyond the stage "
                    f"travel {high} m: set cylinder_positions_m or stage_travel_m"
                )
            self._positions_m = positions.astype(np.float64)
        return self._positions_m

    def _chain_geometry(self) -> tuple[int, float]:
        from sim_backend import dem

        spec = self.config.chain_spec
        chain = dem.build_chain(spec if spec is not None else dem.default_chain_spec())
        return int(chain.n), float(chain.diameter_m)

    def cylinder_at(self, position_m: float) -> int | None:
        """1-based cylinder the laser sees at stage ``position_m`` (m), or ``None`` between."""
        pos = self.cylinder_positions_m
        i = int(np.argmin(np.abs(pos - position_m)))
        if abs(pos[i] - position_m) <= self.config.spot_tolerance_m:
            return i + 1
        return None

    def signal_level(self, position_m: float | None = None) -> float:
        """Vibrometer signal level (0..1) at the stage position (m; default: where it is now)."""
        if self.faults.vibrometer_signal_lost and self.faults.active(self.n_acquisitions):
            return LEVEL_LOST
        if position_m is None:
            position_m = self._inst.stage_position_m()
        return LEVEL_ON_TARGET if self.cylinder_at(position_m) is not None else LEVEL_BETWEEN

    @property
    def dem_stats(self) -> DemStats:
        """DEM calls, cache hits and DEM wall seconds."""
        return self._dem.stats

    def take_dem_runs(self) -> list[dict[str, Any]]:
        """Meta (drive, integrator, step, error estimate, energy residual) of every distinct DEM
        run served since the last call; the run engine stores them in the run file."""
        return self._dem.take_served()

    # --- trigger and acquisition ----------------------------------------------------------------
    def fire_trigger(self, plays: list[ChannelPlay] | tuple[ChannelPlay, ...]) -> None:
        """The generator fired (``*TRG``): ``plays`` are the channels whose output is ON. The
        armed digitiser (on the wired terminal) latches the event."""
        self.n_triggers += 1
        range_name, delay_s, sensitivity = self._inst.vibrometer_range_and_delay()
        event = TriggerEvent(
            time_s=self.clock.now(),
            plays=tuple(plays),
            stage_position_m=self._inst.stage_position_m(),
            range_name=range_name,
            decoder_delay_s=delay_s,
            sensitivity_m_per_s_per_V=sensitivity,
            signal_lost=self.faults.vibrometer_signal_lost
            and self.faults.active(self.n_acquisitions),
        )
        dig = self._armed
        if dig is not None and dig.armed and dig.trigger_terminal == self.config.trigger_terminal:
            self._latched = event

    def _digitiser_armed(self, dig: SimDigitiser) -> None:
        self._armed = dig
        self._latched = None

    def _take_trigger(self, dig: SimDigitiser) -> TriggerEvent | None:
        if self._armed is not dig:
            return None
        event, self._latched = self._latched, None
        self._armed = None
        return event

    def _acquisition_done(self) -> None:
        self.n_acquisitions += 1

    def dem_key(
        self, play: ChannelPlay, duration_s: float, rate_Hz: float
    ) -> tuple[DemKey, NDArray[np.float64]]:
        """The DEM key (and normalised waveform) for what ``play`` drives."""
        direction = self.config.channel_direction(play.channel)
        if direction is None:
            raise InstrumentError(
                f"simulated bench: generator channel {play.channel} drives no piezo "
                f"(direction_channel {dict(self.config.direction_channel)})"
            )
        peak = float(np.max(np.abs(play.samples))) if play.samples.size else 0.0
        norm = play.samples / peak if peak > 0 else play.samples
        act = self.config.actuator
        key = DemKey(
            direction=direction,
            kind=act.kind,
            amplitude=act.drive_amplitude(0.5 * play.amplitude_Vpp * peak),
            waveform_sha1=waveform_digest(norm),
            waveform_rate_Hz=float(play.sample_rate_Hz),
            duration_s=duration_s,
            sample_rate_Hz=rate_Hz,
        )
        return key, norm

    def _noise_rng(self, stream: str, cylinder: int | None) -> np.random.Generator:
        """The noise generator of one record: seeded by the world's seed, what was measured
        (DEM key digest, cylinder) and how many records of it came before. So a point's
        averages get fresh noise, and a resumed run (a new world) draws the same noise for a
        point as an uninterrupted run would."""
        count_key = (stream, -1 if cylinder is None else cylinder)
        count = self._stream_counts.get(count_key, 0)
        self._stream_counts[count_key] = count + 1
        digest = hashlib.sha1(f"{stream}|{count_key[1]}|{count}".encode()).digest()
        words = [int.from_bytes(digest[i : i + 4], "little") for i in range(0, 16, 4)]
        return np.random.default_rng([self.config.seed, *words])

    def _render(
        self,
        event: TriggerEvent,
        config: AcquisitionConfig,
        rate_Hz: float,
        ranges_V: tuple[float, float],
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], dict[str, Any]]:
        """Velocity and reference volts ``[n_samples]`` for one triggered record."""
        cfg = self.config
        t = (np.arange(config.n_samples) - config.n_pretrigger) / rate_Hz
        cylinder = self.cylinder_at(event.stage_position_m)
        meta: dict[str, Any] = {
            "cylinder": cylinder,
            "stage_position_m": event.stage_position_m,
            "vibrometer_range": event.range_name,
            "trigger_time_s": event.time_s,
            "acquisition": self.n_acquisitions,
        }
        if len(event.plays) > 1:
            raise InstrumentError(
                "simulated bench: both generator outputs were on at the trigger; the simulation "
                "drives one end of the chain at a time"
            )
        velocity = np.zeros_like(t)
        reference = np.zeros_like(t)
        noise = cfg.vibrometer_noise_m_per_s_rms
        stream = f"quiet|{config.n_samples}|{config.n_pretrigger}|{rate_Hz!r}"
        if event.plays:
            play = event.plays[0]
            reference = play.volts(t)
            t_end = float(t[-1]) + 1.0 / rate_Hz
            duration = max(cfg.dem_duration_s, math.ceil(t_end * 1e3) / 1e3)
            dem_rate = cfg.dem_sample_rate_Hz or rate_Hz
            key, norm = self.dem_key(play, duration, dem_rate)
            stream = f"{key.waveform_sha1}|{key.direction}|{key.amplitude!r}|{stream}"
            meta.update(direction=key.direction, drive_amplitude=key.amplitude)
            if cylinder is not None and not event.signal_lost:
                rec = self._dem.record(key, norm)
                velocity = on_grid(
                    rec.time_s, rec.velocity_m_per_s[cylinder - 1], t - event.decoder_delay_s
                )
        if cylinder is None or event.signal_lost:
            noise = max(noise, 1e-6) * NO_SIGNAL_NOISE_FACTOR
            meta["signal"] = "lost" if event.signal_lost else "between cylinders"
        rng = self._noise_rng(stream, cylinder)
        sens = event.sensitivity_m_per_s_per_V
        decoded = decoder_output(velocity, sens, cfg.vibrometer_full_scale_V, noise, rng)
        velocity_V = digitise(decoded, ranges_V[0], cfg.adc_bits, cfg.digitiser_noise_V_rms, rng)
        reference_V = digitise(reference, ranges_V[1], cfg.adc_bits, cfg.digitiser_noise_V_rms, rng)
        meta["sensitivity_m_per_s_per_V"] = sens
        return velocity_V, reference_V, meta
