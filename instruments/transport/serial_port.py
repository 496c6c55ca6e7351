"""Transport on pyserial: a port name or a pyserial URL (``"COM3"``, ``"/dev/ttyUSB0"``,
``"socket://host:port"``, ``"loop://"``)."""

from __future__ import annotations

from typing import Any

from instruments.errors import InstrumentError, InstrumentTimeout
from instruments.transport.block import encode_block
from instruments.transport.reply_text import reply_text

__all__ = ["SerialTransport"]


class SerialTransport:
    """A :class:`~instruments.interfaces.Transport` on a serial line, line-oriented.

    Parameters
    ----------
    port:
        Port or pyserial URL.
    name:
        Instrument name used in error messages.
    timeout_s:
        Per-read timeout in s; setting it sets pyserial's read and write timeouts.
    baudrate, bytesize, parity, stopbits:
        Line settings (default 115200 8N1: Polytec OFV-5000 and Zaber ASCII).
    termination:
        Line termination written after each command; replies end at ``"\\n"`` (``"\\r"`` stripped).
    """

    def __init__(
        self,
        port: str,
        *,
        name: str = "instrument",
        timeout_s: float = 2.0,
        baudrate: int = 115200,
        bytesize: int = 8,
        parity: str = "N",
        stopbits: float = 1,
        termination: str = "\n",
        serial_factory: Any = None,
    ) -> None:
        import serial

        self.name = f"{name} ({port})"
        self._timeout_s = float(timeout_s)
        self._term = termination.encode()
        factory = serial_factory or serial.serial_for_url
        try:
            self._port: Any = factory(
                port,
                baudrate=baudrate,
                bytesize=bytesize,
                parity=parity,
                stopbits=stopbits,
                timeout=self.timeout_s,
                write_timeout=self.timeout_s,
            )
        except (serial.SerialException, ValueError) as exc:
            raise InstrumentError(f"{self.name}: cannot open serial port ({exc})") from None

    @property
    def timeout_s(self) -> float:
        """Per-read timeout in s (sets the port's ``timeout`` and ``write_timeout``)."""
        return self._timeout_s

    @timeout_s.setter
    def timeout_s(self, value: float) -> None:
        self._timeout_s = float(value)
        port = getattr(self, "_port", None)
        if port is not None:
            port.timeout = self._timeout_s
            port.write_timeout = self._timeout_s

    def clear(self) -> None:
        """Drop whatever is waiting in the input buffer (a late reply)."""
        try:
            self._port.reset_input_buffer()
        except Exception as exc:
            raise InstrumentError(f"{self.name}: cannot clear the input ({exc})") from None

    def _send(self, what: str, payload: bytes) -> None:
        try:
            self._port.write(payload)
            self._port.flush()
        except Exception as exc:
            raise InstrumentError(f"{self.name}: cannot send {what!r} ({exc})") from None

    def _readline(self, what: str) -> str:
        try:
            raw = self._port.read_until(b"\n")
        except Exception as exc:
            raise InstrumentError(f"{self.name}: read after {what!r} failed ({exc})") from None
        if not raw.endswith(b"\n"):
            raise InstrumentTimeout(
                f"{self.name}: no reply to {what!r} within {self.timeout_s:g} s"
            )
        return reply_text(raw).strip("\r\n")

    def write(self, command: str) -> None:
        self._send(command, command.encode("ascii") + self._term)

    def query(self, command: str) -> str:
        try:  # a stale line (late reply, unsolicited message) must not answer this query
            self._port.reset_input_buffer()
        except Exception:
            pass
        self.write(command)
        return self._readline(command)

    def write_block(self, header: str, data: bytes) -> None:
        self._send(header, header.encode("ascii") + encode_block(data) + self._term)

    def read(self) -> str:
        return self._readline("read")

    def close(self) -> None:
        try:
            self._port.close()
        except Exception:
            pass
