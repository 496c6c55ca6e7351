"""The text of an instrument's reply line: UTF-8 where the bytes are, else Latin-1, where every
byte is a character. Replies are ASCII but for the micro sign of a unit (``7.3 µs``), which a
controller may send as one byte (0xB5, Latin-1 and Windows-1252) or as UTF-8 (0xC2 0xB5); a
strict ASCII decoding refused the line (the PLACE project's Polytec driver met it in the lab)."""

from __future__ import annotations

__all__ = ["reply_text", "reread_as_utf8"]


def reply_text(raw: bytes) -> str:
    """``raw`` as text: UTF-8 when it is valid UTF-8, else Latin-1."""
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def reread_as_utf8(text: str) -> str:
    """A line decoded as Latin-1 (how the VISA transport reads), read again as UTF-8 where its
    bytes are UTF-8 (``'Âµs'`` -> ``'µs'``); unchanged otherwise."""
    try:
        return text.encode("latin-1").decode("utf-8")
    except (UnicodeEncodeError, UnicodeDecodeError):
        return text
