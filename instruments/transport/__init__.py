"""Transports: one message channel to one instrument (VISA, serial, scripted fake).

:func:`open_transport` picks the implementation from the resource string: VISA resource
strings (``TCPIP...``, ``USB...``, ``GPIB...``, ``ASRL...::INSTR``) go to pyvisa, everything
else (``COM3``, ``/dev/ttyUSB0``, ``socket://``, ``loop://``) to pyserial.
"""

from __future__ import annotations

import re
from typing import Any

from instruments.errors import InstrumentError
from instruments.interfaces import Transport
from instruments.transport.block import encode_block, parse_block
from instruments.transport.fake import ScriptedTransport

__all__ = [
    "ScriptedTransport",
    "encode_block",
    "open_transport",
    "parse_block",
    "same_resource_key",
]

_VISA_PREFIXES = ("TCPIP", "USB", "GPIB", "VXI", "PXI")


def _is_visa(resource: str) -> bool:
    upper = resource.upper()
    if upper.startswith(_VISA_PREFIXES):
        return True
    return upper.startswith("ASRL") and "::" in upper


#: a Windows serial port name as pyserial opens it (not case sensitive there)
_COM_PORT = re.compile(r"COM(\d+)", re.IGNORECASE)
#: a VISA serial resource: its port (a number, or a device path) and the optional class
_ASRL = re.compile(r"ASRL(.+?)(?:::INSTR)?", re.IGNORECASE)


def same_resource_key(resource: str) -> str:
    """One spelling of ``resource`` for the spellings that certainly open the same resource
    the way :func:`open_transport` opens them, and only those: surrounding whitespace; a VISA
    resource string (as :func:`open_transport` tells one) case aside, its defaults written
    out by pyvisa's own parser (``TCPIP::h::INSTR`` is ``TCPIP0::h::inst0::INSTR``,
    ``GPIB::5`` is ``GPIB0::5::INSTR``); a VISA serial resource's ``::INSTR``, its port
    path keeping its case (``ASRL/dev/ttyUSB0``: Linux names are case sensitive); a Windows
    port name (``com3`` is ``COM3``). Anything else (a device path, a pyserial URL) as
    written. Two spellings that may or may not name one resource keep two keys: ``COM3`` is
    not ``ASRL3::INSTR`` (pyserial and VISA; NI-VISA may alias ASRL numbers), nor ``ASRL3``
    (pyserial opens that), nor a host name its address (no name lookup), nor ``hislip0``
    ``inst0``, nor ``TCPIP1`` ``TCPIP0``, nor a ``/dev/serial/by-id`` link its tty. Not the
    instrument locks' :func:`daq.instrument_lock.canonical`, which makes one key of whatever
    may be one device (a lock taken twice over is the safe side there)."""
    a = resource.strip()
    if not _is_visa(a):
        com = _COM_PORT.fullmatch(a)
        return f"COM{com.group(1)}" if com is not None else a
    asrl = _ASRL.fullmatch(a)
    if asrl is not None:
        return f"ASRL{asrl.group(1)}::INSTR"
    from pyvisa import rname

    upper = a.upper()  # pyvisa's parser reads the class (INSTR, SOCKET) upper case only
    try:
        return rname.to_canonical_name(upper).upper()  # its default "inst0" lower case
    except rname.InvalidResourceName:
        return upper


def open_transport(
    resource: str,
    *,
    name: str = "instrument",
    timeout_s: float = 5.0,
    baud_rate: int | None = None,
    visa_backend: str = "@py",
    **settings: Any,
) -> Transport:
    """Open ``resource`` on pyvisa or pyserial.

    ``baud_rate`` sets the line speed of a serial port or of a VISA ``ASRL`` resource (VISA
    defaults to 9600 baud; Zaber ASCII and the Polytec OFV-5000 ship at 115200; ``None``: the
    transport's default). ``visa_backend`` is the VISA library of a VISA resource (``"@py"``
    pyvisa-py, ``"@ivi"`` an installed NI-VISA or Keysight IO Libraries). ``settings`` go to
    :class:`~instruments.transport.visa.VisaTransport` (terminations) or
    :class:`~instruments.transport.serial_port.SerialTransport` (``parity``...). An empty or
    unknown resource raises :class:`InstrumentError` naming it.
    """
    if not isinstance(resource, str) or not resource.strip():
        raise InstrumentError(f"{name}: empty instrument resource {resource!r}")
    if not timeout_s > 0:
        raise InstrumentError(f"{name}: timeout must be > 0 s, got {timeout_s!r}")
    if _is_visa(resource):
        from instruments.transport.visa import VisaTransport

        return VisaTransport(
            resource,
            name=name,
            timeout_s=timeout_s,
            baud_rate=baud_rate,
            backend=visa_backend,
            **settings,
        )
    from instruments.transport.serial_port import SerialTransport

    if baud_rate is not None:
        settings["baudrate"] = baud_rate
    return SerialTransport(resource, name=name, timeout_s=timeout_s, **settings)
