"""Transport on pyvisa: any VISA resource string (default backend pyvisa-py, ``"@py"``)."""

from __future__ import annotations

import re
import sys
from typing import Any

from instruments.errors import DriverNotInstalledError, InstrumentError, InstrumentTimeout
from instruments.transport.block import encode_block
from instruments.transport.reply_text import reread_as_utf8

__all__ = ["VisaTransport"]

_CHECK = "check that the instrument is on, its address in the bench file and the cable or network"


def _one_line(exc: BaseException) -> str:
    """An exception's text on one line: pyvisa-py's messages hold line breaks, and the command
    line shows the first line only, which lost the reason and the hint after it."""
    return " ".join(str(exc).split())


def _open_hint(resource: str, backend: str, why: str) -> str | None:
    """What to change when pyvisa-py cannot open ``resource`` for a reason of its own."""
    if backend != "@py":
        return None
    if "PyUSB" in why or "pyusb" in why:
        return (
            "pyvisa-py opens USB instruments only with pyusb and libusb installed "
            "(pip install pyusb); or set visa_backend: '@ivi' in the bench file to use the "
            "NI-VISA or Keysight IO Libraries of this PC"
        )
    if re.fullmatch(r"ASRL\d+::INSTR", resource.strip().upper()) and sys.platform != "win32":
        return (
            "pyvisa-py reads ASRLn as COMn on Windows only: here name the port itself "
            "(ASRL/dev/ttyUSB0::INSTR, or just /dev/ttyUSB0)"
        )
    return None


class VisaTransport:
    """A :class:`~instruments.interfaces.Transport` on one pyvisa message-based resource.

    Parameters
    ----------
    resource:
        VISA resource string, e.g. ``"TCPIP::10.0.0.5::INSTR"``.
    name:
        Instrument name used in error messages.
    timeout_s:
        Per-call timeout in s.
    backend:
        pyvisa backend (``"@py"`` pyvisa-py; ``"@sim"`` pyvisa-sim; ``""`` the NI/Keysight VISA).
    read_termination, write_termination:
        Line terminations (default ``"\\n"``).
    baud_rate:
        Line speed of an ``ASRL`` (serial) resource; VISA's own default is 9600 baud.

    A dead link (``ConnectionRefusedError``, ``BrokenPipeError``, any ``OSError`` or
    ``VisaIOError`` that is not a timeout) becomes an :class:`InstrumentError` naming the
    instrument, its resource and what to check.
    """

    def __init__(
        self,
        resource: str,
        *,
        name: str = "instrument",
        timeout_s: float = 5.0,
        backend: str = "@py",
        read_termination: str = "\n",
        write_termination: str = "\n",
        baud_rate: int | None = None,
        resource_manager: Any = None,
    ) -> None:
        import pyvisa

        self.name = f"{name} ({resource})"
        self.timeout_s = float(timeout_s)
        self._errors: tuple[type[BaseException], ...] = (pyvisa.errors.VisaIOError,)
        try:
            rm = resource_manager or pyvisa.ResourceManager(backend)
        except (OSError, ValueError) as exc:
            raise DriverNotInstalledError(
                f"{self.name}: VISA backend {backend!r} not available ({_one_line(exc)}); "
                + (
                    "install the NI-VISA or Keysight IO Libraries on this PC, or set "
                    "visa_backend: '@py' in the bench file (pyvisa-py, shipped)"
                    if backend != "@py"
                    else "reinstall pyvisa-py (pip install pyvisa-py)"
                )
            ) from None
        try:
            res: Any = rm.open_resource(resource)
            self._res: Any = res
        except Exception as exc:  # pyvisa raises several types for a bad/unknown resource
            raise InstrumentError(
                f"{self.name}: cannot open VISA resource ({_one_line(exc)}); "
                + (_open_hint(resource, backend, str(exc)) or _CHECK)
            ) from None
        try:
            self.timeout_s = float(timeout_s)
            self._res.read_termination = read_termination
            self._res.write_termination = write_termination
            self._res.encoding = "latin-1"  # every byte a character: a reply with a micro sign
            # reads (pyvisa's default, ASCII, raised UnicodeDecodeError on it); see reply_text
            if baud_rate is not None:
                self._res.baud_rate = int(baud_rate)
        except BaseException:  # the session is not ours to hand back: closed, not leaked
            self.close()
            raise
        self._write_term = write_termination.encode()
        import pyvisa.constants as vc

        ops = vc.BufferOperation
        #: a serial line keeps a late reply in its receive buffer, to answer the next query:
        #: every query empties it first (pyvisa-py's serial session does so on
        #: ``discard_read_buffer`` only, NI-VISA without I/O on the read and receive buffers)
        self._serial = resource.upper().startswith("ASRL")
        if not self._serial:
            self._flush_mask = int(ops.discard_read_buffer_no_io)
        elif backend == "@py":
            self._flush_mask = int(ops.discard_read_buffer)
        else:
            self._flush_mask = int(ops.discard_read_buffer_no_io | ops.discard_receive_buffer)

    @property
    def timeout_s(self) -> float:
        """Per-call timeout in s (sets the VISA resource's timeout)."""
        return self._timeout_s

    @timeout_s.setter
    def timeout_s(self, value: float) -> None:
        self._timeout_s = float(value)
        res = getattr(self, "_res", None)
        if res is not None:
            res.timeout = round(self._timeout_s * 1000)

    def _call(self, what: str, fn: Any, *args: Any) -> Any:
        try:
            return fn(*args)
        except self._errors as exc:
            if "TMO" in str(exc) or "Timeout" in str(exc) or "timeout" in str(exc):
                raise InstrumentTimeout(
                    f"{self.name}: no reply to {what!r} within {self.timeout_s:g} s"
                ) from None
            raise InstrumentError(
                f"{self.name}: {what!r} failed ({_one_line(exc)}); {_CHECK}"
            ) from None
        except OSError as exc:  # ConnectionRefusedError, BrokenPipeError, reset: a dead link
            if isinstance(exc, TimeoutError):
                raise InstrumentTimeout(
                    f"{self.name}: no reply to {what!r} within {self.timeout_s:g} s"
                ) from None
            raise InstrumentError(
                f"{self.name}: link lost at {what!r} ({type(exc).__name__}: {_one_line(exc)}); "
                f"{_CHECK}"
            ) from None

    def clear(self) -> None:
        """Device clear (IEEE 488.2 / VISA ``viClear``): the instrument drops its output queue
        and pending input; anything still waiting here is flushed too."""
        self._call("device clear", self._res.clear)
        self._flush_input()

    def _flush_input(self) -> None:
        """Drop what waits to be read here (never raises: not every session has a buffer)."""
        try:
            self._res.flush(self._flush_mask)
        except Exception:
            pass

    def write(self, command: str) -> None:
        self._call(command, self._res.write, command)

    def query(self, command: str) -> str:
        if self._serial:  # a stale line must not answer this query
            self._flush_input()
        return reread_as_utf8(str(self._call(command, self._res.query, command))).strip()

    def write_block(self, header: str, data: bytes) -> None:
        payload = header.encode() + encode_block(data) + self._write_term
        self._call(header, self._res.write_raw, payload)

    def read(self) -> str:
        return reread_as_utf8(str(self._call("read", self._res.read))).strip()

    def close(self) -> None:
        try:
            self._res.close()
        except Exception:
            pass
