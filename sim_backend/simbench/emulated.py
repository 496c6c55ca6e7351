"""The simulated rig's instruments: the wire-level emulators (``sim_backend.emulators``) of one
world, on one clock, and the transports the real drivers talk to.

The drivers themselves are opened by the one bench connection, ``daq.connect.connect_bench``,
from a bench file, exactly as on the rig.

The world owns one emulator per instrument and one shared :class:`SimClock`. Each transport it
hands out is a :class:`SimTransport` wrapped so that, before every message, the world pushes its
state into the emulator: the fault plan (generator silent, SCPI error, stage stall / lost
homing, vibrometer signal loss) and the vibrometer's signal level from the stage position. The
generator's ``*TRG`` reaches the world through the emulator's trigger hook.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Any

import numpy as np

from sim_backend.emulators import (
    KeysightEmulator,
    PolytecEmulator,
    SimClock,
    SimTransport,
    ZaberEmulator,
)

if TYPE_CHECKING:
    from sim_backend.simbench.world import ChannelPlay, SimWorld

__all__ = ["INSTRUMENTS", "EmulatedInstruments", "WorldTransport"]

#: the stage the simulated bench moves (the Zaber emulator's model) and its resolution
SIMULATED_STAGE = "X-LSM500A"
SIMULATED_RESOLUTION = 64

INSTRUMENTS: tuple[str, ...] = ("generator", "vibrometer", "stage")
#: default transport timeouts (s, simulated)
TIMEOUT_S = {"generator": 5.0, "vibrometer": 2.0, "stage": 2.0}
_SCPI_ERROR = re.compile(r'^\s*([+-]?\d+)\s*,\s*"?(.*?)"?\s*$')


class WorldTransport:
    """A :class:`SimTransport` that lets the world update its emulator before each message."""

    def __init__(self, inner: SimTransport, instruments: EmulatedInstruments, which: str) -> None:
        self._inner = inner
        self._inst = instruments
        self._which = which
        self.name: str = inner.name

    @property
    def timeout_s(self) -> float:
        return self._inner.timeout_s

    @timeout_s.setter
    def timeout_s(self, value: float) -> None:
        self._inner.timeout_s = value

    def write(self, command: str) -> None:
        self._inst.sync(self._which)
        self._inner.write(command)
        self._inst.after(self._which, command)

    def query(self, command: str) -> str:
        self._inst.sync(self._which)
        reply = self._inner.query(command)
        self._inst.after(self._which, command)
        return reply

    def write_block(self, header: str, data: bytes) -> None:
        self._inst.sync(self._which)
        self._inner.write_block(header, data)

    def read(self) -> str:
        self._inst.sync(self._which)
        return self._inner.read()

    def clear(self) -> None:
        self._inner.clear()

    def close(self) -> None:
        self._inner.close()


class EmulatedInstruments:
    """The emulators of one world, their clock and transports."""

    def __init__(self, world: SimWorld) -> None:
        cfg = world.config
        self.world = world
        self.clock = SimClock(cfg.speedup)
        self.generator = KeysightEmulator()
        self.generator.trigger_hooks.append(self._on_trigger)
        self.vibrometer = (
            PolytecEmulator(range_name=cfg.vibrometer_range)
            if cfg.vibrometer_range is not None
            else PolytecEmulator()
        )
        self.stage = ZaberEmulator(
            self.clock,
            model=SIMULATED_STAGE,
            resolution=SIMULATED_RESOLUTION,
            travel_m=cfg.stage_travel_m,
            speed_m_per_s=cfg.stage_speed_m_per_s,
        )
        self._emulators: dict[str, Any] = {
            "generator": self.generator,
            "vibrometer": self.vibrometer,
            "stage": self.stage,
        }
        #: stage position override for tests that bypass the stage (m), else None
        self.position_m: float | None = None

    # --- transports -----------------------------------------------------------------------
    def transport(self, instrument: str, baud_rate: int | None = None) -> WorldTransport:
        if instrument not in self._emulators:
            raise ValueError(
                f"unknown simulated instrument {instrument!r}; choose from {', '.join(INSTRUMENTS)}"
            )
        inner = SimTransport(
            self._emulators[instrument],
            name=f"{instrument} (simulated)",
            timeout_s=TIMEOUT_S[instrument],
            clock=self.clock,
            baud_rate=baud_rate,
        )
        return WorldTransport(inner, self, instrument)

    def sync(self, which: str) -> None:
        """Push the fault plan and the world's state into emulator ``which``."""
        world = self.world
        faults = world.faults
        on = faults.active(world.n_acquisitions)
        if which == "generator":
            self.generator.responsive = not (on and faults.generator_silent)
            if on and faults.generator_scpi_error is not None:
                m = _SCPI_ERROR.match(faults.generator_scpi_error)
                code, msg = (
                    (int(m.group(1)), m.group(2)) if m else (-300, faults.generator_scpi_error)
                )
                self.generator.push_error(code, msg)
                faults.generator_scpi_error = None  # one-shot: it is in the queue now
        elif which == "vibrometer":
            self.vibrometer.signal_level = world.signal_level(self.stage_position_m())
        elif which == "stage" and on and faults.stage_lost_homing:
            self.stage.lose_homing()
            faults.stage_lost_homing = False  # one-shot: homing again recovers

    def after(self, which: str, command: str) -> None:
        """React to a command that went through (a move starts: the stall fault strikes)."""
        world = self.world
        faults = world.faults
        if (
            which == "stage"
            and " move " in f" {command} "
            and faults.stage_stall
            and faults.active(world.n_acquisitions)
        ):
            self.stage.stall()
            faults.stage_stall = False  # one-shot: the next move may succeed

    # --- state for the world --------------------------------------------------------------
    def stage_position_m(self) -> float:
        if self.position_m is not None:
            return self.position_m
        return float(self.stage.position_m())

    def vibrometer_range_and_delay(self) -> tuple[str, float, float]:
        """The decoder's range name, its signal delay (s) and its sensitivity ((m/s)/V), from
        the emulator's own range table (not the driver's parser: a misread range would
        otherwise be wrong on both sides alike)."""
        vib = self.vibrometer
        return vib.range_name, float(vib.delay_s), float(vib.sensitivity_m_per_s_per_V())

    def _on_trigger(self, fired: tuple[int, ...]) -> None:
        from sim_backend.simbench.world import ChannelPlay

        plays: list[ChannelPlay] = []
        for n in fired:
            ch = self.generator.channels[n]
            if not ch.output_on or ch.function.upper() != "ARB" or ch.waveform.size < 2:
                continue
            # the load setting scales what the generator believes it drives; the amplifier input
            # is high impedance, so the real voltage is the open-circuit one
            load = ch.load_ohm
            k = 1.0 if not np.isfinite(load) else (load + 50.0) / load
            samples = np.asarray(ch.waveform, dtype=np.float64)
            if ch.burst_cycles > 1:
                samples = np.tile(samples, int(ch.burst_cycles))
            plays.append(
                ChannelPlay(
                    channel=n,
                    samples=samples,
                    sample_rate_Hz=float(ch.sample_rate_Hz),
                    amplitude_Vpp=float(ch.amplitude_Vpp) * k,
                    offset_V=float(ch.offset_V) * k,
                )
            )
        self.world.fire_trigger(plays)
