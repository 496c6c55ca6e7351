"""Settings of the simulated world: one frozen, self-validating object, SI units throughout.

The bench connection (``daq.connect``) builds a :class:`SimWorldConfig` from the simulated
bench file; tests build one directly. Every field names its unit; a bad value is refused with a
one-line message naming the field before anything is simulated.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from sim_backend.dem.integrators import integrator_error
from sim_backend.simbench.actuator import ActuatorModel
from sim_backend.simbench.dem_cache import CACHE_BYTES, CACHE_RUNS
from sim_backend.simbench.faults import FaultPlan

__all__ = ["DIRECTIONS", "SimWorldConfig"]

DIRECTIONS: tuple[str, ...] = ("ltr", "rtl")


def _default_direction_channel() -> Mapping[str, int]:
    return MappingProxyType({"ltr": 1, "rtl": 2})


@dataclass(frozen=True)
class SimWorldConfig:
    """Everything that makes the simulated bench behave like the rig.

    Attributes
    ----------
    chain_spec:
        The DEM chain (``sim_backend.dem.ChainSpec``); ``None``: ``default_chain_spec()``.
    direction_channel:
        Generator channel (1-based) whose piezo drives each direction,
        e.g. ``{"ltr": 1, "rtl": 2}``.
    actuator:
        Generator volts -> amplifier -> piezo (m or N).
    cylinder_positions_m:
        Stage position (m) at which the laser hits each cylinder's contact point, shape ``[N]``
        in cylinder order; ``None``: ``first_cylinder_m + i * pitch`` with the chain's diameter
        as pitch (the cylinders are stacked crossed, one diameter apart).
    first_cylinder_m:
        Stage position of cylinder 1 when ``cylinder_positions_m`` is ``None`` (m).
    spot_tolerance_m:
        How far (m) the laser may sit from a cylinder's position and still see it; further away
        the laser is between cylinders: no velocity signal and a low signal level.
    stage_travel_m:
        (low, high) travel of the simulated stage in m.
    stage_speed_m_per_s:
        Stage speed (m/s) for the simulated move durations.
    stage_settle_s:
        Settling time after each move (s, simulated).
    vibrometer_range:
        Initial decoder range name (``None``: the emulator's default).
    vibrometer_full_scale_V:
        The decoder's analog output clips at +/- this (V).
    vibrometer_noise_m_per_s_rms:
        Decoder velocity noise floor (m/s rms) on a good signal.
    digitiser_noise_V_rms:
        Input-referred noise of the digitiser (V rms).
    adc_bits:
        ADC resolution over the selected input range (bits).
    max_rate_Hz:
        Highest sample rate per channel (S/s).
    timebase_Hz:
        Sample clock timebase; rates are coerced to ``timebase_Hz / k`` like a NI device.
    trigger_terminal:
        The digitiser terminal wired to the generator's trigger output (e.g. ``"/Dev1/PFI0"``);
        an acquisition armed on any other terminal never sees the trigger.
    seed:
        Seed of every random number in the world (noise), so a run is reproducible.
    speedup:
        Simulated time runs this many times faster than wall time (0: as fast as possible; 1:
        real time).
    faults:
        The fault plan (mutable, shared with the world).
    dem_duration_s:
        Minimum simulated window after the trigger (s); longer acquisitions extend it.
    dem_sample_rate_Hz:
        DEM output rate (S/s); ``None``: the digitiser's rate (no resampling).
    dem_integrator:
        Integrator name passed to ``simulate()``.
    dem_dt_s:
        Integrator step (s) or ``None`` for the integrator's default.
    dem_cache_size:
        How many DEM runs the cache keeps.
    dem_cache_MB:
        The most megabytes (2**20 bytes) of DEM runs the cache keeps (the newest whatever its
        size): a run holds every cylinder's velocity over the window.
    """

    chain_spec: Any = None
    direction_channel: Mapping[str, int] = field(default_factory=_default_direction_channel)
    actuator: ActuatorModel = field(default_factory=ActuatorModel)
    cylinder_positions_m: tuple[float, ...] | None = None
    first_cylinder_m: float = 0.02
    spot_tolerance_m: float = 2.0e-3
    stage_travel_m: tuple[float, float] = (0.0, 0.5)
    stage_speed_m_per_s: float = 0.025
    stage_settle_s: float = 0.2
    vibrometer_range: str | None = None
    vibrometer_full_scale_V: float = 10.0
    vibrometer_noise_m_per_s_rms: float = 2.0e-6
    digitiser_noise_V_rms: float = 3.0e-4
    adc_bits: int = 16
    max_rate_Hz: float = 2.0e6
    timebase_Hz: float = 100.0e6
    trigger_terminal: str = "/Dev1/PFI0"
    seed: int = 0
    speedup: float = 0.0
    faults: FaultPlan = field(default_factory=FaultPlan)
    dem_duration_s: float = 30.0e-3
    dem_sample_rate_Hz: float | None = None
    dem_integrator: str = "default"
    dem_dt_s: float | None = None
    dem_cache_size: int = CACHE_RUNS
    dem_cache_MB: float = CACHE_BYTES / 2**20

    def __post_init__(self) -> None:
        self._check_direction_channel()
        if not isinstance(self.actuator, ActuatorModel):
            raise ValueError(f"actuator must be an ActuatorModel, got {self.actuator!r}")
        if not isinstance(self.faults, FaultPlan):
            raise ValueError(f"faults must be a FaultPlan, got {self.faults!r}")
        if self.cylinder_positions_m is not None:
            pos = tuple(float(p) for p in self.cylinder_positions_m)
            if len(pos) < 1 or not all(math.isfinite(p) for p in pos):
                raise ValueError("cylinder_positions_m must be finite stage positions (m)")
            object.__setattr__(self, "cylinder_positions_m", pos)
        low, high = (float(v) for v in self.stage_travel_m)
        if not (math.isfinite(low) and math.isfinite(high) and low < high):
            raise ValueError(
                f"stage_travel_m must be (low, high) with low < high, got {(low, high)}"
            )
        object.__setattr__(self, "stage_travel_m", (low, high))
        if self.cylinder_positions_m is not None:
            outside = [p for p in self.cylinder_positions_m if not low <= p <= high]
            if outside:
                raise ValueError(
                    f"cylinder_positions_m: {outside[0]!r} m is outside the stage travel "
                    f"{low}..{high} m"
                )
        positive = (
            "spot_tolerance_m",
            "stage_speed_m_per_s",
            "vibrometer_full_scale_V",
            "max_rate_Hz",
            "timebase_Hz",
            "dem_duration_s",
            "dem_cache_MB",
        )
        non_negative = (
            "first_cylinder_m",
            "stage_settle_s",
            "vibrometer_noise_m_per_s_rms",
            "digitiser_noise_V_rms",
            "speedup",
        )
        for name in positive + non_negative:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"{name} must be a number, got {value!r}")
            if not math.isfinite(value) or value < 0 or (name in positive and value == 0):
                sign = "> 0" if name in positive else ">= 0"
                raise ValueError(f"{name} must be finite and {sign}, got {value!r}")
        for name in ("dem_sample_rate_Hz", "dem_dt_s"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be > 0 or None, got {value!r}")
        for name, lo, hi in (("adc_bits", 1, 32), ("dem_cache_size", 1, 10_000)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
                raise ValueError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
        why = integrator_error(self.dem_integrator)
        if why is not None:
            raise ValueError(f"dem_integrator: {why}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {self.seed!r}")
        if not isinstance(self.trigger_terminal, str) or not self.trigger_terminal:
            raise ValueError("trigger_terminal must name a terminal, e.g. '/Dev1/PFI0'")
        if self.vibrometer_range is not None and not isinstance(self.vibrometer_range, str):
            raise ValueError(
                f"vibrometer_range must be a range name, got {self.vibrometer_range!r}"
            )

    def _check_direction_channel(self) -> None:
        dc = dict(self.direction_channel)
        if set(dc) != set(DIRECTIONS):
            raise ValueError(
                f"direction_channel must map exactly 'ltr' and 'rtl' to channels, got {dc!r}"
            )
        for direction, channel in dc.items():
            if isinstance(channel, bool) or channel not in (1, 2):
                raise ValueError(
                    f"direction_channel[{direction!r}] must be generator channel 1 or 2, "
                    f"got {channel!r}"
                )
        if dc["ltr"] == dc["rtl"]:
            raise ValueError("direction_channel: 'ltr' and 'rtl' need different channels")
        object.__setattr__(self, "direction_channel", MappingProxyType(dc))

    def channel_direction(self, channel: int) -> str | None:
        """The direction driven by generator ``channel`` (1-based), or ``None``."""
        for direction, ch in self.direction_channel.items():
            if ch == channel:
                return direction
        return None
