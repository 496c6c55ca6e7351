"""A scripted fake transport for unit tests: expects an exact command sequence.

Script entries are ``(command, reply)``: ``reply`` is ``None`` for a write, a string for a query,
or an exception instance raised when that command arrives (e.g. to simulate a timeout). Binary
blocks are recorded as ``(header, data)`` in :attr:`blocks` and appear in :attr:`sent` as
``header + "#<n><len>" + "<N bytes>"``.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable

from instruments.errors import InstrumentError, InstrumentTimeout
from instruments.transport.block import encode_block

__all__ = ["ScriptedTransport"]

Step = tuple[str, "str | BaseException | None"]


class ScriptedTransport:
    """A :class:`~instruments.interfaces.Transport` that plays a script.

    With ``strict=False`` the script is optional: every write is recorded and queries are
    answered from ``replies`` (a dict command -> reply) or raise :class:`InstrumentTimeout`.
    """

    def __init__(
        self,
        script: Iterable[Step] = (),
        *,
        name: str = "fake",
        timeout_s: float = 1.0,
        strict: bool = True,
        replies: dict[str, str] | None = None,
    ) -> None:
        self.name = name
        self.timeout_s = timeout_s
        self.strict = strict
        self.replies = dict(replies or {})
        self.script: deque[Step] = deque(script)
        self.sent: list[str] = []
        self.blocks: list[tuple[str, bytes]] = []
        self.closed = False
        self._pending: list[str] = []

    def _next(self, command: str, is_query: bool) -> str | None:
        if self.closed:
            raise InstrumentError(f"{self.name}: transport closed, cannot send {command!r}")
        self.sent.append(command)
        if not self.strict:
            if not is_query:
                return None
            if command in self.replies:
                return self.replies[command]
            raise InstrumentTimeout(
                f"{self.name}: no reply to {command!r} within {self.timeout_s:g} s"
            )
        if not self.script:
            raise AssertionError(f"{self.name}: unexpected command {command!r} (script ended)")
        expected, reply = self.script.popleft()
        if expected != command:
            raise AssertionError(f"{self.name}: expected {expected!r}, got {command!r}")
        if isinstance(reply, BaseException):
            raise reply
        if is_query and reply is None:
            raise InstrumentTimeout(
                f"{self.name}: no reply to {command!r} within {self.timeout_s:g} s"
            )
        return reply

    def write(self, command: str) -> None:
        reply = self._next(command, is_query=False)
        if reply is not None:
            self._pending.append(reply)

    def query(self, command: str) -> str:
        reply = self._next(command, is_query=True)
        assert reply is not None
        return reply

    def write_block(self, header: str, data: bytes) -> None:
        block = encode_block(data)
        head = block[: len(block) - len(data)].decode()
        self.blocks.append((header, bytes(data)))
        self._next(f"{header}{head}<{len(data)} bytes>", is_query=False)

    def read(self) -> str:
        if self._pending:
            return self._pending.pop(0)
        raise InstrumentTimeout(f"{self.name}: no reply to read within {self.timeout_s:g} s")

    def close(self) -> None:
        self.closed = True

    @property
    def done(self) -> bool:
        """True when every scripted step was consumed."""
        return not self.script
