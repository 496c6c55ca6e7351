"""Wire-level emulators of the bench instruments, and a Transport onto them.

The real drivers (``instruments.keysight/polytec/zaber``) run on :class:`SimTransport`
unchanged. The emulators know nothing about the DEM: the simulated world couples them.
"""

from sim_backend.emulators.bench import EmulatedInstruments, make_emulators
from sim_backend.emulators.clock import SimClock
from sim_backend.emulators.keysight import ChannelState, KeysightEmulator
from sim_backend.emulators.polytec import PolytecEmulator
from sim_backend.emulators.transport import Emulator, SimTransport
from sim_backend.emulators.zaber import ZaberEmulator

__all__ = [
    "ChannelState",
    "EmulatedInstruments",
    "Emulator",
    "KeysightEmulator",
    "PolytecEmulator",
    "SimClock",
    "SimTransport",
    "ZaberEmulator",
    "make_emulators",
]
