"""The simulated digitiser: the :class:`instruments.interfaces.Digitiser` contract on the world.

It behaves like the NI-DAQmx one: rates coerced to the timebase, ranges to the device's ranges,
a finite triggered acquisition armed before the generator fires, and a timeout (in simulated
time) when no trigger arrives on the configured terminal.
"""

from __future__ import annotations

import logging
import re
from typing import TYPE_CHECKING, Any

import numpy as np

from instruments.errors import InstrumentError, InstrumentTimeout, LimitError
from instruments.interfaces import Acquisition, AcquisitionConfig
from sim_backend.simbench.signal_chain import coerce_input_range, coerce_sample_rate

if TYPE_CHECKING:
    from sim_backend.simbench.world import SimWorld

__all__ = ["SimDigitiser"]

log = logging.getLogger(__name__)

_CHANNEL = re.compile(r"^(?P<dev>[A-Za-z][\w-]*)/ai(?P<n>\d+)$")


class SimDigitiser:
    """A triggered two-channel digitiser (velocity and drive reference) on the simulated world.

    Parameters
    ----------
    world:
        The world that produces the signals and the trigger.
    device:
        Device name, e.g. ``"Dev1"``; channels must be ``"<device>/ai<n>"``.
    n_channels:
        Analog inputs on the device.
    terminal_config:
        The inputs' terminal configuration as the bench file names it (reported only: the
        simulated inputs have no ground loops).
    """

    def __init__(
        self,
        world: SimWorld,
        device: str = "Dev1",
        n_channels: int = 8,
        terminal_config: str = "default",
    ) -> None:
        self._world = world
        self.device = device
        self.terminal_config = terminal_config
        self.n_channels = n_channels
        self._config: AcquisitionConfig | None = None
        self._rate_Hz: float | None = None
        self._ranges_V: tuple[float, float] | None = None
        self._armed = False
        self._closed = False

    @property
    def name(self) -> str:
        return f"digitiser ({self.device})"

    @property
    def armed(self) -> bool:
        """Whether an acquisition waits for its trigger."""
        return self._armed

    @property
    def trigger_terminal(self) -> str | None:
        """The terminal the configured acquisition waits on."""
        return None if self._config is None else self._config.trigger_source

    def _check_open(self) -> None:
        if self._closed:
            raise InstrumentError(f"{self.name}: closed")

    def _check_channel(self, field_name: str, channel: str) -> None:
        m = _CHANNEL.match(channel)
        if m is None or m.group("dev") != self.device or int(m.group("n")) >= self.n_channels:
            raise LimitError(
                f"{self.name}: {field_name} {channel!r} is not an input of this device "
                f"({self.device}/ai0 .. {self.device}/ai{self.n_channels - 1})"
            )

    def configure(self, config: AcquisitionConfig) -> float:
        """Set up the acquisition; returns the coerced sample rate (S/s)."""
        self._check_open()
        self._check_channel("velocity_channel", config.velocity_channel)
        self._check_channel("reference_channel", config.reference_channel)
        if config.velocity_channel == config.reference_channel:
            raise LimitError(f"{self.name}: velocity and reference need different channels")
        cfg = self._world.config
        rate = coerce_sample_rate(config.sample_rate_Hz, cfg.max_rate_Hz, cfg.timebase_Hz)
        ranges = (
            coerce_input_range(config.velocity_range_V, "velocity range"),
            coerce_input_range(config.reference_range_V, "reference range"),
        )
        self._config = config
        self._rate_Hz = rate
        self._ranges_V = ranges
        self._armed = False
        return rate

    def arm(self) -> None:
        """Start waiting for the trigger (a trigger that came before is not seen)."""
        self._check_open()
        if self._config is None:
            raise InstrumentError(f"{self.name}: arm() before configure()")
        self._armed = True
        self._world._digitiser_armed(self)

    def read(self) -> Acquisition:
        """Wait (simulated time, up to the timeout) for the triggered record and return it."""
        self._check_open()
        if not self._armed or self._config is None:
            raise InstrumentError(f"{self.name}: read() before arm()")
        assert self._rate_Hz is not None and self._ranges_V is not None
        config = self._config
        self._armed = False
        world = self._world
        event = world._take_trigger(self)
        faults_on = world.faults.active(world.n_acquisitions)
        if event is None or (faults_on and world.faults.digitiser_timeout):
            world.clock.sleep(config.timeout_s)
            why = (
                "injected fault" if event is not None else f"no trigger on {config.trigger_source}"
            )
            raise InstrumentTimeout(
                f"{self.name}: read timed out after {config.timeout_s:g} s ({why})"
            )
        velocity_V, reference_V, meta = world._render(event, config, self._rate_Hz, self._ranges_V)
        if faults_on and world.faults.digitiser_nan:
            velocity_V = np.full_like(velocity_V, np.nan)
            meta["fault"] = "digitiser_nan"
        post = config.n_samples - config.n_pretrigger
        world.clock.sleep(post / self._rate_Hz)
        world._acquisition_done()
        return Acquisition(
            sample_rate_Hz=self._rate_Hz,
            velocity_V=velocity_V,
            reference_V=reference_V,
            n_pretrigger=config.n_pretrigger,
            meta=meta,
        )

    def snapshot(self) -> dict[str, Any]:
        cfg = self._world.config
        snap: dict[str, Any] = {
            "kind": "SimDigitiser",
            "device": self.device,
            "terminal_config": self.terminal_config,
            "adc_bits": cfg.adc_bits,
            "noise_V_rms": cfg.digitiser_noise_V_rms,
            "max_rate_Hz": cfg.max_rate_Hz,
        }
        if self._config is not None:
            c = self._config
            snap.update(
                sample_rate_Hz=self._rate_Hz,
                n_samples=c.n_samples,
                n_pretrigger=c.n_pretrigger,
                velocity_channel=c.velocity_channel,
                reference_channel=c.reference_channel,
                velocity_range_V=self._ranges_V[0] if self._ranges_V else None,
                reference_range_V=self._ranges_V[1] if self._ranges_V else None,
                trigger_source=c.trigger_source,
                timeout_s=c.timeout_s,
            )
        return snap

    def safe_state(self) -> None:
        """Stop any armed acquisition (never raises)."""
        self._armed = False

    def close(self) -> None:
        self._armed = False
        self._closed = True
