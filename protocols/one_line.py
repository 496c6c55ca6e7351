"""The first line of an error's message, for the one-line messages the commands print (h5py's
messages quote themselves and run over several lines: HDF5's error stack)."""

from __future__ import annotations

__all__ = ["first_line"]


def first_line(exc: BaseException) -> str:
    """The first line of ``exc``'s message, or its class name when it has none. A line quoted as
    a whole (``KeyError`` quotes its argument; h5py's messages come so) loses that one pair of
    quotes; one that only ends in a quote keeps it (``no reply to '*OPC?'``)."""
    lines = str(exc).splitlines()
    line = lines[0] if lines else ""
    if len(line) >= 2 and line[0] == line[-1] and line[0] in "'\"":
        line = line[1:-1]
    return line or type(exc).__name__
