"""``protocols.one_line.first_line``: the one line the commands print of an error's message."""

from __future__ import annotations

import pytest

from instruments.errors import InstrumentError
from protocols.one_line import first_line


@pytest.mark.parametrize(
    ("exc", "line"),
    [
        (InstrumentError(), "InstrumentError"),  # no message: its class, not an IndexError
        (OSError(""), "OSError"),
        (KeyError("x"), "x"),  # KeyError quotes its argument
        (
            OSError('"Unable to open file (file signature not found)"\nHDF5 stack'),
            "Unable to open file (file signature not found)",
        ),
        (InstrumentError("no reply to '*OPC?'"), "no reply to '*OPC?'"),  # its last quote kept
        (ValueError("'VOLT' out of range\nmore"), "'VOLT' out of range"),
        (ValueError("first\nsecond"), "first"),
    ],
)
def test_first_line(exc: BaseException, line: str) -> None:
    assert first_line(exc) == line
