"""The simulated bench: the real drivers on emulated instruments coupled to a DEM-driven world.

Usage (the run engine's bench assembly does the same from a bench file)::

    world = SimWorld(SimWorldConfig(seed=1))
    gen = KeysightGenerator(world.transport("generator"), limits)   # the real driver
    clock = world.clock
    stage = ZaberStage(world.transport("stage"), ZaberSettings(model="X-LSM500A", clock=clock))
    daq = world.digitiser()
    world.faults.stage_stall = True                                  # fault injection
    world.dem_stats                                                  # DEM calls / hits / s

or ``build_rig(world)`` for all four with settings consistent with the world.
"""

from sim_backend.bench.actuator import ActuatorModel
from sim_backend.bench.config import SimWorldConfig
from sim_backend.bench.dem_cache import DemStats
from sim_backend.bench.digitiser import SimDigitiser
from sim_backend.bench.faults import FaultPlan
from sim_backend.bench.rig import SimRig, build_rig
from sim_backend.bench.world import ChannelPlay, SimWorld, TriggerEvent

__all__ = [
    "ActuatorModel",
    "ChannelPlay",
    "DemStats",
    "FaultPlan",
    "SimDigitiser",
    "SimRig",
    "SimWorld",
    "SimWorldConfig",
    "TriggerEvent",
    "build_rig",
]
