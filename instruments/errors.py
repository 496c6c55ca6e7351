"""Exceptions raised by instruments and their transports.

Every message names the instrument and, where there is one, the command, so a one-line report
tells the physicist what failed:
``"generator (TCPIP::10.0.0.5::INSTR): no reply to '*OPC?' within 5 s"``.
"""

from __future__ import annotations

__all__ = [
    "DriverNotInstalledError",
    "InstrumentError",
    "InstrumentTimeout",
    "LimitError",
    "MoveTimeout",
    "NotHomedError",
    "ReplyError",
    "SignalLostError",
    "StallError",
]


class InstrumentError(RuntimeError):
    """An instrument refused, failed or said something we cannot read."""


class InstrumentTimeout(InstrumentError, TimeoutError):
    """No reply within the transport's timeout."""


class ReplyError(InstrumentError):
    """A malformed reply, or an error reported by the instrument (SCPI error queue, rejection)."""


class LimitError(InstrumentError, ValueError):
    """A setting outside the safety or device limits; refused before anything was sent."""


class NotHomedError(InstrumentError):
    """A stage move asked for before homing."""


class StallError(InstrumentError):
    """A stage stalled or hit a limit while moving."""


class MoveTimeout(InstrumentError):
    """A stage answered every poll but its move or homing did not end in time: a blocked or
    too slow axis, not a dead link (not an :class:`InstrumentTimeout`)."""


class SignalLostError(InstrumentError):
    """The vibrometer's optical signal level is too low to trust the velocity."""


class DriverNotInstalledError(InstrumentError):
    """A vendor driver (NI-DAQmx, a VISA library) is missing on this machine."""
