"""Typed contracts of the four bench instruments and of the transport under them.

These Protocols are what the run engine, the simulated bench and the GUI rely on; the drivers
in this package (and the simulated digitiser in ``sim_backend``) implement them. All values are
SI: metres, seconds, hertz, volts, metres per second.

Settings objects are frozen dataclasses that validate themselves on construction, so a bad value
is refused before a byte is sent to an instrument.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from instruments.burst import Burst
from instruments.errors import LimitError

__all__ = [
    "Acquisition",
    "AcquisitionConfig",
    "BurstConfig",
    "Digitiser",
    "FunctionGenerator",
    "Instrument",
    "Stage",
    "Transport",
    "Vibrometer",
]

TriggerSource = Literal["bus", "external", "immediate"]


@runtime_checkable
class Transport(Protocol):
    """A message channel to one instrument (pyvisa, pyserial, simulated or scripted fake).

    ``name`` names the instrument in error messages. Every call honours ``timeout_s`` and raises
    :class:`instruments.errors.InstrumentTimeout` (naming the instrument and the command) when no
    reply comes in time.
    """

    name: str
    timeout_s: float

    def write(self, command: str) -> None:
        """Send one command line (the transport adds the termination)."""
        ...

    def query(self, command: str) -> str:
        """Send one command and return its reply line, termination stripped."""
        ...

    def write_block(self, header: str, data: bytes) -> None:
        """Send ``header`` followed by ``data`` as an IEEE 488.2 definite-length block
        (``#<n><length><bytes>``), then the termination."""
        ...

    def read(self) -> str:
        """Read one reply line, termination stripped."""
        ...

    def close(self) -> None:
        """Release the port or resource; further calls raise."""
        ...


class Instrument(Protocol):
    """What every bench instrument offers."""

    def snapshot(self) -> dict[str, Any]:
        """Settings and identity, JSON-serialisable, for the run file's provenance."""
        ...

    def safe_state(self) -> None:
        """Bring the instrument to a state where nothing moves or drives (never raises on a
        dead link: it logs and returns)."""
        ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class BurstConfig:
    """One triggered burst on a generator channel.

    Attributes
    ----------
    shape:
        The burst shape (centre frequency, cycles or width), normalised to peak 1.
    amplitude_Vpp:
        Generator amplitude setting, peak-to-peak volts, at the output-load setting. A burst
        normalised to peak 1 peaks at ``amplitude_Vpp / 2`` if the generator maps its DAC's
        full scale to it, and up to ``arb_peak_factor`` times that if it maps the data's own
        peak-to-peak (``instruments.keysight``: the limits are checked at the larger).
    sample_rate_Hz:
        Arbitrary-waveform sample rate in Sa/s.
    offset_V:
        DC offset in volts.
    trigger_source:
        ``"bus"`` (``*TRG``), ``"external"`` or ``"immediate"`` (the Keysight driver refuses
        ``"external"``: it turns off the trigger out that starts the digitiser).
    """

    shape: Burst
    amplitude_Vpp: float
    sample_rate_Hz: float = 1.0e6
    offset_V: float = 0.0
    trigger_source: TriggerSource = "bus"

    def __post_init__(self) -> None:
        for name in ("amplitude_Vpp", "sample_rate_Hz", "offset_V"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise LimitError(f"burst {name} must be finite, got {value!r}")
        if self.amplitude_Vpp <= 0:
            raise LimitError(f"burst amplitude must be > 0 Vpp, got {self.amplitude_Vpp!r}")
        if self.sample_rate_Hz <= 0:
            raise LimitError(f"burst sample rate must be > 0 Sa/s, got {self.sample_rate_Hz!r}")


@runtime_checkable
class FunctionGenerator(Instrument, Protocol):
    """A two-channel arbitrary function generator that plays one burst per trigger."""

    def identify(self) -> str: ...

    def configure_burst(self, channel: int, config: BurstConfig) -> None:
        """Upload and arm a burst on ``channel`` (1-based); the output stays off."""
        ...

    def output(self, channel: int, on: bool) -> None: ...

    def output_state(self, channel: int) -> bool:
        """Read back whether ``channel``'s output is on (confirms the safe state)."""
        ...

    def trigger(self) -> None:
        """Fire the armed burst (bus trigger)."""
        ...

    def wait_complete(self, timeout_s: float | None = None) -> None:
        """Block until the previous commands completed (``*OPC?``)."""
        ...

    def errors(self) -> list[str]:
        """Drain the error queue; returns the messages (empty when none)."""
        ...


@runtime_checkable
class Vibrometer(Instrument, Protocol):
    """A laser Doppler vibrometer controller with a velocity decoder."""

    def identify(self) -> str: ...

    def velocity_range(self) -> str:
        """The decoder range as the controller names it (e.g. ``"VD-09 10mm/s/V"``)."""
        ...

    def set_velocity_range(self, name: str) -> None: ...

    def sensitivity_m_per_s_per_V(self) -> float:
        """Scale of the analog output in (m/s)/V, parsed from the range name."""
        ...

    def bandwidth_Hz(self) -> float: ...

    def signal_delay_s(self) -> float:
        """Decoder delay in s, subtracted when aligning velocity with the drive."""
        ...

    def signal_level(self) -> float:
        """Optical signal level, 0 (none) to 1 (full)."""
        ...


@runtime_checkable
class Stage(Instrument, Protocol):
    """A motorised linear stage carrying the vibrometer head. Positions in metres."""

    def home(self, cancel: threading.Event | None = None) -> None:
        """Home and block until done; when ``cancel`` is set meanwhile, stop the axis and return
        early (not homed)."""
        ...

    def is_homed(self) -> bool: ...

    def move_to(self, position_m: float) -> None:
        """Move and block until idle; refused when not homed or outside :meth:`limits`."""
        ...

    def position(self) -> float: ...

    def stop(self) -> None:
        """Start to decelerate the axis; returns at once."""
        ...

    def is_moving(self) -> bool:
        """Whether the axis moves (decelerating after :meth:`stop` included)."""
        ...

    def limits(self) -> tuple[float, float]:
        """(low, high) travel in m: device limits intersected with the bench's soft limits."""
        ...


@dataclass(frozen=True)
class AcquisitionConfig:
    """A finite, triggered two-channel acquisition (velocity and drive reference).

    Attributes
    ----------
    sample_rate_Hz:
        Requested rate per channel in S/s (the device may coerce it; see ``Acquisition``).
    n_samples:
        Samples per channel, pre-trigger included.
    n_pretrigger:
        Samples kept before the trigger.
    velocity_channel, reference_channel:
        Physical channel names (e.g. ``"Dev1/ai0"``).
    velocity_range_V, reference_range_V:
        Input ranges, +/- volts.
    trigger_source:
        Terminal of the start trigger (e.g. ``"/Dev1/PFI0"``).
    timeout_s:
        How long :meth:`Digitiser.read` waits for the trigger and the data.
    """

    sample_rate_Hz: float
    n_samples: int
    n_pretrigger: int = 0
    velocity_channel: str = "Dev1/ai0"
    reference_channel: str = "Dev1/ai1"
    velocity_range_V: float = 10.0
    reference_range_V: float = 10.0
    trigger_source: str = "/Dev1/PFI0"
    timeout_s: float = 10.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sample_rate_Hz) and self.sample_rate_Hz > 0):
            raise LimitError(f"sample rate must be > 0 S/s, got {self.sample_rate_Hz!r}")
        if self.n_samples < 2:
            raise LimitError(f"need at least 2 samples, got {self.n_samples}")
        if not 0 <= self.n_pretrigger < self.n_samples:
            raise LimitError(
                f"pre-trigger samples must be in [0, {self.n_samples}), got {self.n_pretrigger}"
            )
        for name in ("velocity_range_V", "reference_range_V", "timeout_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise LimitError(f"{name} must be > 0, got {value!r}")


@dataclass
class Acquisition:
    """One acquired record.

    Attributes
    ----------
    sample_rate_Hz:
        The rate actually used (read back from the device), S/s.
    velocity_V, reference_V:
        Shape ``[n_samples]`` float64, volts at the digitiser input.
    n_pretrigger:
        Samples before the trigger; ``time_s`` is 0 at the trigger.
    """

    sample_rate_Hz: float
    velocity_V: NDArray[np.float64]
    reference_V: NDArray[np.float64]
    n_pretrigger: int = 0
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def time_s(self) -> NDArray[np.float64]:
        """Shape ``[n_samples]``, seconds from the trigger."""
        n = self.velocity_V.shape[0]
        return (np.arange(n) - self.n_pretrigger) / self.sample_rate_Hz


@runtime_checkable
class Digitiser(Instrument, Protocol):
    """A triggered two-channel digitiser."""

    def configure(self, config: AcquisitionConfig) -> float:
        """Set up the acquisition; returns the coerced sample rate in S/s."""
        ...

    def arm(self) -> None:
        """Start waiting for the trigger."""
        ...

    def read(self) -> Acquisition:
        """Wait (up to the configured timeout) for the triggered record and return it."""
        ...
