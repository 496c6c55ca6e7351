"""A Transport whose other end is an emulator: the real drivers run on it unchanged."""

from __future__ import annotations

from typing import Protocol

from instruments.clock import Clock
from instruments.errors import InstrumentError, InstrumentTimeout
from instruments.transport.block import encode_block

__all__ = ["Emulator", "SimTransport"]


class Emulator(Protocol):
    """An instrument emulator: one message in (bytes, termination stripped), reply or None."""

    responsive: bool

    def handle(self, message: bytes) -> str | None: ...


class SimTransport:
    """:class:`instruments.interfaces.Transport` on an :class:`Emulator`.

    A query that gets no reply (emulator silent or not responsive) raises
    :class:`InstrumentTimeout` after ``clock.sleep(timeout_s)`` (simulated time passes as it
    would on the bench; any clock with ``now``/``sleep`` works, e.g. :class:`SimClock`).
    A reply of several lines (late replies arriving before the current one) is read line by
    line: the query returns the first, :meth:`read` the next; a line not read stays for the
    next query unless the link is serial (below). :meth:`clear` is a device clear
    (pending lines dropped, the emulator's ``clear()`` called when it has one).
    ``baud_rate``: the line speed this end talks at (``None``: not a serial line); an emulator
    with a ``baud_rate`` of its own hears only garbage at another speed and never answers.
    """

    def __init__(
        self,
        emulator: Emulator,
        name: str = "sim",
        timeout_s: float = 1.0,
        clock: Clock | None = None,
        baud_rate: int | None = None,
    ) -> None:
        self.emulator = emulator
        self.baud_rate = baud_rate
        self.name = name
        self.timeout_s = float(timeout_s)
        self.clock = clock
        self.closed = False
        self._pending: list[str] = []
        self.log: list[str] = []

    def _send(self, message: bytes, what: str) -> str | None:
        if self.closed:
            raise InstrumentError(f"{self.name}: transport closed, cannot send {what!r}")
        self.log.append(what)
        if not self.emulator.responsive:
            return None
        theirs = getattr(self.emulator, "baud_rate", None)
        if self.baud_rate is not None and theirs is not None and theirs != self.baud_rate:
            return None  # framing errors: the instrument sees no command
        return self.emulator.handle(message)

    def _timeout(self, what: str) -> InstrumentTimeout:
        if self.clock is not None:
            self.clock.sleep(self.timeout_s)
        return InstrumentTimeout(f"{self.name}: no reply to {what!r} within {self.timeout_s:g} s")

    def write(self, command: str) -> None:
        reply = self._send(command.encode("ascii"), command)
        if reply is not None:
            self._pending.extend(reply.split("\n"))

    def query(self, command: str) -> str:
        """Send ``command`` and read one line. A serial line (``baud_rate`` set) drops what was
        waiting first, as the driver's serial transport flushes its receive buffer; on a
        network link (VXI-11, sockets) nothing is flushed, so a line left unread (a late
        reply) answers this query, as the instrument's output queue would."""
        if self.baud_rate is not None:
            self._pending.clear()
        reply = self._send(command.encode("ascii"), command)
        if reply is not None:
            self._pending.extend(reply.split("\n"))
        if not self._pending or not self.emulator.responsive:
            raise self._timeout(command)
        return self._pending.pop(0)

    def write_block(self, header: str, data: bytes) -> None:
        reply = self._send(header.encode("ascii") + encode_block(data), header)
        if reply is not None:
            self._pending.extend(reply.split("\n"))

    def clear(self) -> None:
        """Device clear: drop what is waiting on both ends."""
        self._pending.clear()
        clear = getattr(self.emulator, "clear", None)
        if clear is not None and self.emulator.responsive:
            clear()

    def read(self) -> str:
        if self._pending and self.emulator.responsive:
            return self._pending.pop(0)
        raise self._timeout("read")

    def close(self) -> None:
        self.closed = True
