"""IEEE 488.2 definite-length binary blocks: ``#<n><length><bytes>``."""

from __future__ import annotations

__all__ = ["encode_block", "parse_block"]


def encode_block(data: bytes) -> bytes:
    """``#<n><length><data>`` with ``n`` the number of digits of ``length`` (1..9)."""
    length = str(len(data))
    if len(length) > 9:
        raise ValueError(f"binary block of {len(data)} bytes is too long for IEEE 488.2")
    return b"#" + str(len(length)).encode() + length.encode() + data


def parse_block(raw: bytes) -> tuple[bytes, bytes]:
    """Split ``raw`` (starting at ``#``) into (block payload, the bytes after it).

    Raises ValueError on a malformed header or a short payload.
    """
    if len(raw) < 2 or raw[:1] != b"#" or not raw[1:2].isdigit() or raw[1:2] == b"0":
        raise ValueError("binary block must start with '#<n>' with n in 1..9")
    n = int(raw[1:2])
    digits = raw[2 : 2 + n]
    if len(digits) != n or not digits.isdigit():
        raise ValueError(f"binary block length field {digits!r} is not {n} digits")
    length = int(digits)
    start = 2 + n
    payload = raw[start : start + length]
    if len(payload) != length:
        raise ValueError(f"binary block announces {length} bytes, got {len(payload)}")
    return payload, raw[start + length :]
