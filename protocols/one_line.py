"""The first line of an error's message, for the one-line messages the commands print (h5py's
messages quote themselves and run over several lines: HDF5's error stack)."""

from __future__ import annotations

__all__ = ["first_line"]


def first_line(exc: BaseException) -> str:
    """The first line of ``exc``'s message without h5py's quotes, or its class name."""
    return (str(exc).strip("'\"").splitlines() or [type(exc).__name__])[0]
