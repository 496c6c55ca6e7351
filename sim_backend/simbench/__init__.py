"""The simulated rig: emulated instruments coupled to a DEM-driven world, and its digitiser.

Not to be confused with a *bench file* (``protocols/benches/*.yaml``, schema in
``protocols/bench.py``), which describes a bench, simulated or real. The real drivers are
opened on this rig by the one bench connection, ``daq.connect.connect_bench``, from a simulated
bench file, exactly as on the lab's rig::

    bench = connect_bench()                   # the shipped simulated bench file
    bench.world.faults.stage_stall = True     # fault injection on the rig behind the drivers
    bench.world.dem_stats                     # DEM calls / hits / s

Tests of the world itself build one directly: ``SimWorld(SimWorldConfig(seed=1))``, then
``world.transport("generator")`` and ``world.digitiser()``.
"""

from sim_backend.simbench.actuator import ActuatorModel
from sim_backend.simbench.config import SimWorldConfig
from sim_backend.simbench.dem_cache import DemStats
from sim_backend.simbench.digitiser import SimDigitiser
from sim_backend.simbench.faults import FaultPlan
from sim_backend.simbench.world import ChannelPlay, SimWorld, TriggerEvent

__all__ = [
    "ActuatorModel",
    "ChannelPlay",
    "DemStats",
    "FaultPlan",
    "SimDigitiser",
    "SimWorld",
    "SimWorldConfig",
    "TriggerEvent",
]
