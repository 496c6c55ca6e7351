"""The actuator model: generator volts -> power amplifier -> piezo displacement or force.

The bench drives the chain with a piezo stack behind a linear power amplifier. The model is a
static linear gain (the amplifier and the piezo are flat far above the 5-15 kHz bands), so the
chain sees the generator's waveform scaled:

* ``kind="displacement"``: wall displacement [m] = V_gen * amplifier_gain_V_per_V * piezo_m_per_V
* ``kind="force"``:        end force [N]        = V_gen * amplifier_gain_V_per_V * force_N_per_V

Default calibration (plausible bench numbers, state them when you report a simulated run):
amplifier 20 V/V, piezo 0.05 um/V, so 1 um of wall displacement per generator volt
(peak). The 33500B's range then spans 10 mVpp -> 5 nm peak (linear, << delta0 ~ 1.15 um) to
10 Vpp -> 5 um peak (about 4 delta0, strongly nonlinear). In force mode 0.5 N/V at the piezo:
10 N per generator volt, so 10 mVpp -> 0.05 N (<< F0 = 5 N) and 10 Vpp -> 50 N (10 F0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

__all__ = ["ActuatorKind", "ActuatorModel"]

ActuatorKind = Literal["displacement", "force"]


@dataclass(frozen=True)
class ActuatorModel:
    """Linear actuator chain from the generator output to the chain's drive.

    Attributes
    ----------
    kind:
        ``"displacement"`` (the piezo is a moving Hertz wall) or ``"force"`` (a prescribed
        force on the end cylinder).
    amplifier_gain_V_per_V:
        Power-amplifier voltage gain, V/V, > 0.
    piezo_m_per_V:
        Piezo free stroke per volt at its terminals, m/V (used when ``kind="displacement"``).
    force_N_per_V:
        Piezo force per volt at its terminals, N/V (used when ``kind="force"``).
    """

    kind: ActuatorKind = "displacement"
    amplifier_gain_V_per_V: float = 20.0
    piezo_m_per_V: float = 5.0e-8
    force_N_per_V: float = 0.5

    def __post_init__(self) -> None:
        if self.kind not in ("displacement", "force"):
            raise ValueError(f"actuator.kind must be 'displacement' or 'force', got {self.kind!r}")
        for name in ("amplifier_gain_V_per_V", "piezo_m_per_V", "force_N_per_V"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"actuator.{name} must be a number, got {value!r}")
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"actuator.{name} must be finite and > 0, got {value!r}")

    @property
    def si_per_generator_V(self) -> float:
        """Drive (m or N, see :attr:`unit`) per volt at the generator output."""
        per_piezo_V = self.piezo_m_per_V if self.kind == "displacement" else self.force_N_per_V
        return self.amplifier_gain_V_per_V * per_piezo_V

    @property
    def unit(self) -> str:
        """SI unit of the drive: ``"m"`` or ``"N"``."""
        return "m" if self.kind == "displacement" else "N"

    def drive_amplitude(self, generator_peak_V: float) -> float:
        """Peak drive (m or N) for a generator peak voltage (V)."""
        return generator_peak_V * self.si_per_generator_V

    def generator_peak_V(self, drive_amplitude: float) -> float:
        """Generator peak voltage (V) that gives a peak drive (m or N): the inverse."""
        return drive_amplitude / self.si_per_generator_V
