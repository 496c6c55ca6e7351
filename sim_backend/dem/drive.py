"""What drives a simulated run: a burst or a sampled waveform, as a displacement or a force."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from instruments.burst import Burst

__all__ = ["Drive"]


@dataclass(frozen=True, eq=False)
class Drive:
    """One drive of a simulated run.

    Attributes
    ----------
    direction: ``"ltr"`` (actuator at cylinder #1) or ``"rtl"`` (actuator at cylinder #N).
    kind: ``"displacement"`` (the actuator is a Hertz wall moving by ``amplitude * w(t)``, m) or
        ``"force"`` (``amplitude * w(t)`` N on the end cylinder, on top of the preload).
    amplitude: peak of the drive in SI (m or N); >= 0.
    burst: the Gaussian burst shape (``instruments.burst.Burst``), or ``None``.
    waveform: ``(samples [L], sample_rate_Hz)``: normalised samples played from ``t = delay_s``,
        linearly interpolated, zero after the last sample; or ``None``. Exactly one of
        ``burst`` / ``waveform``.
    delay_s: start of the burst/waveform after the trigger (s), >= 0.
    """

    direction: Literal["ltr", "rtl"]
    kind: Literal["displacement", "force"] = "displacement"
    amplitude: float = 0.0
    burst: Burst | None = None
    waveform: tuple[NDArray[np.float64], float] | None = None
    delay_s: float = 0.0

    def __post_init__(self) -> None:
        if self.direction not in ("ltr", "rtl"):
            raise ValueError(f"drive direction must be 'ltr' or 'rtl', got {self.direction!r}")
        if self.kind not in ("displacement", "force"):
            raise ValueError(f"drive kind must be 'displacement' or 'force', got {self.kind!r}")
        if not (math.isfinite(self.amplitude) and self.amplitude >= 0):
            raise ValueError(f"drive amplitude must be finite and >= 0, got {self.amplitude!r}")
        if (self.burst is None) == (self.waveform is None):
            raise ValueError("give exactly one of drive burst / waveform")
        if not (math.isfinite(self.delay_s) and self.delay_s >= 0):
            raise ValueError(f"drive delay_s must be >= 0, got {self.delay_s!r}")
        if self.waveform is not None:
            samples, rate = self.waveform
            arr = np.asarray(samples, dtype=np.float64)
            if arr.ndim != 1 or arr.size < 2 or not np.all(np.isfinite(arr)):
                raise ValueError("drive waveform must be a 1-D array of >= 2 finite samples")
            if not (math.isfinite(rate) and rate > 0):
                raise ValueError(f"drive waveform rate must be > 0 Hz, got {rate!r}")

    @property
    def units(self) -> str:
        """``"m"`` for a displacement drive, ``"N"`` for a force drive."""
        return "m" if self.kind == "displacement" else "N"

    def value(self, t_s: NDArray[np.float64]) -> NDArray[np.float64]:
        """The drive (m or N) at times ``t_s`` (s from the trigger), same shape."""
        t = np.asarray(t_s, dtype=np.float64) - self.delay_s
        if self.burst is not None:
            return self.amplitude * self.burst.at(t)
        assert self.waveform is not None
        samples, rate = self.waveform
        arr = np.asarray(samples, dtype=np.float64)
        x = t * rate
        out = np.interp(x, np.arange(arr.size, dtype=np.float64), arr, left=0.0, right=0.0)
        return self.amplitude * out
