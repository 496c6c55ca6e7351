"""The three emulators on one clock, and the real drivers opened on them.

The simulated world (``sim_backend.bench``) can build its instrument side from this: it reads
the emulators' state (generator channels, stage position, vibrometer range) and sets theirs
(vibrometer signal level, faults); the run engine talks to the drivers only.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from instruments.keysight import GeneratorLimits, KeysightGenerator
from instruments.polytec import PolytecSettings, PolytecVibrometer
from instruments.zaber import ZaberSettings, ZaberStage
from sim_backend.emulators.clock import SimClock
from sim_backend.emulators.keysight import KeysightEmulator
from sim_backend.emulators.polytec import PolytecEmulator
from sim_backend.emulators.transport import SimTransport
from sim_backend.emulators.zaber import ZaberEmulator

__all__ = ["EmulatedInstruments", "make_emulators"]


@dataclass
class EmulatedInstruments:
    """Emulators, their transports and the shared simulated clock."""

    clock: SimClock
    generator: KeysightEmulator
    vibrometer: PolytecEmulator
    stage: ZaberEmulator
    generator_transport: SimTransport
    vibrometer_transport: SimTransport
    stage_transport: SimTransport

    def transport(self, instrument: str) -> SimTransport:
        """The transport to ``"generator"``, ``"vibrometer"`` or ``"stage"``."""
        try:
            return {
                "generator": self.generator_transport,
                "vibrometer": self.vibrometer_transport,
                "stage": self.stage_transport,
            }[instrument]
        except KeyError:
            raise ValueError(f"no emulated instrument {instrument!r}") from None

    def drivers(
        self,
        limits: GeneratorLimits,
        stage_settings: ZaberSettings | None = None,
        vibrometer_settings: PolytecSettings | None = None,
    ) -> tuple[KeysightGenerator, PolytecVibrometer, ZaberStage]:
        """The real drivers on the emulators; the stage polls on the simulated clock."""
        ss = replace(stage_settings or ZaberSettings(), clock=self.clock)
        if ss.model is None and ss.microstep_m is None:
            ss = replace(ss, model=self.stage.model)
        return (
            KeysightGenerator(self.generator_transport, limits),
            PolytecVibrometer(self.vibrometer_transport, vibrometer_settings),
            ZaberStage(self.stage_transport, ss),
        )


def make_emulators(
    clock: SimClock | None = None,
    *,
    stage_travel_m: tuple[float, float] = (0.0, 0.5),
    stage_speed_m_per_s: float = 0.025,
    stage_model: str = "X-LSM500A",
    vibrometer_range: str = "VD-09 10mm/s/V",
    timeouts_s: tuple[float, float, float] = (5.0, 2.0, 2.0),
) -> EmulatedInstruments:
    """Generator, vibrometer and stage emulators on ``clock`` (new one, speed-up 0, if None).

    ``timeouts_s``: (generator, vibrometer, stage) transport timeouts in s.
    """
    clk = clock if clock is not None else SimClock()
    gen = KeysightEmulator()
    vib = PolytecEmulator(range_name=vibrometer_range)
    stage = ZaberEmulator(
        clk, model=stage_model, travel_m=stage_travel_m, speed_m_per_s=stage_speed_m_per_s
    )
    return EmulatedInstruments(
        clk,
        gen,
        vib,
        stage,
        SimTransport(gen, "generator (sim)", timeouts_s[0], clk),
        SimTransport(vib, "vibrometer (sim)", timeouts_s[1], clk),
        SimTransport(stage, "stage (sim)", timeouts_s[2], clk),
    )
