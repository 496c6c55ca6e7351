"""Transports: one message channel to one instrument (VISA, serial, scripted fake).

:func:`open_transport` picks the implementation from the resource string: VISA resource
strings (``TCPIP...``, ``USB...``, ``GPIB...``, ``ASRL...::INSTR``) go to pyvisa, everything
else (``COM3``, ``/dev/ttyUSB0``, ``socket://``, ``loop://``) to pyserial.
"""

from __future__ import annotations

from typing import Any

from instruments.errors import InstrumentError
from instruments.interfaces import Transport
from instruments.transport.block import encode_block, parse_block
from instruments.transport.fake import ScriptedTransport

__all__ = ["ScriptedTransport", "encode_block", "open_transport", "parse_block"]

_VISA_PREFIXES = ("TCPIP", "USB", "GPIB", "VXI", "PXI")


def _is_visa(resource: str) -> bool:
    upper = resource.upper()
    if upper.startswith(_VISA_PREFIXES):
        return True
    return upper.startswith("ASRL") and "::" in upper


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
