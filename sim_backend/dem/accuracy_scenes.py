"""Scenes for accuracy studies: one chain, one burst drive, one recorded window.

A scene is everything that fixes the exact solution: the chain (its YAML), the drive (direction,
kind, amplitude, burst centre frequency and cycles), the window and the record rate. Its
:meth:`AccuracyScene.digest` keys the converged reference on disk.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from typing import Literal

from instruments.burst import Burst
from sim_backend.dem.chain import Chain, build_chain
from sim_backend.dem.drive import Drive
from sim_backend.dem.simulation import SimResult, simulate
from sim_backend.dem.spec import ChainSpec, benchmark_chain_spec

__all__ = ["BUILTIN_SCENES", "DEFAULT_F_HZ", "AccuracyScene", "builtin_scene"]

#: the paper's input frequencies (Hz)
DEFAULT_F_HZ = {"ltr": 8.92e3, "rtl": 6.63e3}
#: built-in scene name -> (one-line description)
BUILTIN_SCENES = {
    "linear": "LTR displacement burst of 0.01 delta0 (contacts stay closed: the linear regime)",
    "highamp": "LTR displacement burst of 4 um (about 3.5 delta0: contacts open and close)",
}


@dataclass(frozen=True)
class AccuracyScene:
    """One trajectory to measure integrators on (SI units).

    name: label; chain_spec: the chain; direction: ``"ltr"``/``"rtl"``; kind:
    ``"displacement"`` (m) or ``"force"`` (N); amplitude: burst peak (m or N);
    f_center_Hz, cycles: the Gaussian burst; duration_s: recorded window (s);
    sample_rate_Hz: record rate (Hz), which also caps the integrator step at 1 / rate.
    """

    name: str
    chain_spec: ChainSpec
    direction: Literal["ltr", "rtl"]
    kind: Literal["displacement", "force"]
    amplitude: float
    f_center_Hz: float
    cycles: float
    duration_s: float
    sample_rate_Hz: float

    def __post_init__(self) -> None:
        for label, value in (
            ("amplitude", self.amplitude),
            ("f_center_Hz", self.f_center_Hz),
            ("cycles", self.cycles),
            ("duration_s", self.duration_s),
            ("sample_rate_Hz", self.sample_rate_Hz),
        ):
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"scene {self.name}: {label} must be finite and > 0, got {value}")

    def chain(self) -> Chain:
        """The built chain (cached by content in :func:`build_chain`)."""
        return build_chain(self.chain_spec)

    def drive(self) -> Drive:
        """The scene's one drive."""
        burst = Burst(self.f_center_Hz, cycles=self.cycles)
        return Drive(
            direction=self.direction, kind=self.kind, amplitude=self.amplitude, burst=burst
        )

    def simulate(
        self,
        integrator: str,
        dt_s: float,
        dashpot_kick: Literal["midpoint", "heun3"] = "midpoint",
    ) -> SimResult:
        """The scene run by the compiled ``integrator`` at step ``dt_s`` (s)."""
        return simulate(
            self.chain(),
            [self.drive()],
            duration_s=self.duration_s,
            sample_rate_Hz=self.sample_rate_Hz,
            integrator=integrator,
            dt_s=dt_s,
            dashpot_kick=dashpot_kick,
        )

    @property
    def n_samples(self) -> int:
        """Recorded samples S = floor(duration * rate) + 1."""
        return math.floor(self.duration_s * self.sample_rate_Hz + 1e-9) + 1

    def driven_far(self) -> tuple[int, int]:
        """0-based (driven cylinder, far cylinder) indices in cylinder order #1..#N."""
        n = self.chain().n
        return (0, n - 1) if self.direction == "ltr" else (n - 1, 0)

    def digest(self, extra: str = "") -> str:
        """SHA-256 (hex) of the chain YAML, the drive, the window and the rate (and ``extra``,
        e.g. the reference method)."""
        payload = json.dumps(
            {
                "chain_yaml": self.chain_spec.to_yaml(),
                "direction": self.direction,
                "kind": self.kind,
                "amplitude": repr(float(self.amplitude)),
                "f_center_Hz": repr(float(self.f_center_Hz)),
                "cycles": repr(float(self.cycles)),
                "duration_s": repr(float(self.duration_s)),
                "sample_rate_Hz": repr(float(self.sample_rate_Hz)),
                "extra": extra,
            },
            sort_keys=True,
        )
        return hashlib.sha256(payload.encode()).hexdigest()


def builtin_scene(
    name: str,
    *,
    chain_spec: ChainSpec | None = None,
    duration_s: float = 10e-3,
    sample_rate_Hz: float = 250e3,
) -> AccuracyScene:
    """A scene of :data:`BUILTIN_SCENES` on ``chain_spec`` (default: the paper's chain with the
    contact dashpot of the recorded measurements, :func:`benchmark_chain_spec`)."""
    if name not in BUILTIN_SCENES:
        raise ValueError(f"unknown scene {name!r}; choose from {', '.join(BUILTIN_SCENES)}")
    spec = chain_spec if chain_spec is not None else benchmark_chain_spec()
    if name == "linear":
        amplitude = 0.01 * build_chain(spec).delta0_m
    else:
        amplitude = 4.0e-6
    return AccuracyScene(
        name=name,
        chain_spec=spec,
        direction="ltr",
        kind="displacement",
        amplitude=amplitude,
        f_center_Hz=DEFAULT_F_HZ["ltr"],
        cycles=5.0,
        duration_s=duration_s,
        sample_rate_Hz=sample_rate_Hz,
    )
