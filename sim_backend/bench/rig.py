"""The real drivers assembled on a simulated world (tests, benchmark, rehearsals).

The run engine's bench assembly (``daq/bench_assembly.py``) does the same from a bench file;
this is the minimal form with settings consistent with :class:`SimWorldConfig`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sim_backend.bench.digitiser import SimDigitiser
from sim_backend.bench.world import SimWorld

__all__ = ["SimRig", "build_rig"]


@dataclass
class SimRig:
    """Generator, vibrometer, stage (real drivers) and the simulated digitiser on one world."""

    world: SimWorld
    generator: Any
    vibrometer: Any
    stage: Any
    digitiser: SimDigitiser

    def safe_state(self) -> None:
        """Every instrument's safe state (outputs off, stage stopped, acquisition stopped)."""
        for inst in (self.generator, self.stage, self.vibrometer, self.digitiser):
            inst.safe_state()


def build_rig(world: SimWorld) -> SimRig:
    """Open the drivers on the world's transports (ImportError while the drivers are missing)."""
    from sim_backend.bench import _instruments

    generator, vibrometer, stage = _instruments.build_drivers(world)
    return SimRig(world, generator, vibrometer, stage, world.digitiser())
