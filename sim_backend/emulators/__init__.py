"""Wire-level emulators of the bench instruments, and a Transport onto them.

The real drivers (``instruments.keysight/polytec/zaber``) run on :class:`SimTransport`
unchanged. The emulators know nothing about the DEM: the simulated rig
(``sim_backend.simbench``) couples them to one world and one clock.
"""

from sim_backend.emulators.clock import SimClock
from sim_backend.emulators.keysight import ChannelState, KeysightEmulator
from sim_backend.emulators.polytec import PolytecEmulator
from sim_backend.emulators.transport import Emulator, SimTransport
from sim_backend.emulators.zaber import ZaberEmulator

__all__ = [
    "ChannelState",
    "Emulator",
    "KeysightEmulator",
    "PolytecEmulator",
    "SimClock",
    "SimTransport",
    "ZaberEmulator",
]
