"""Blocks, the scripted fake, the serial transport (pyserial loop://) and the factory."""

from __future__ import annotations

import pytest

from instruments.errors import InstrumentError, InstrumentTimeout
from instruments.transport import ScriptedTransport, encode_block, open_transport, parse_block
from instruments.transport.serial_port import SerialTransport


def test_block_round_trip_and_malformed() -> None:
    raw = encode_block(b"\x01\x02" * 6)
    assert raw == b"#212" + b"\x01\x02" * 6
    assert parse_block(raw + b"\n") == (b"\x01\x02" * 6, b"\n")
    for bad in (b"#0", b"#3ab", b"#15ab", b"x"):
        with pytest.raises(ValueError):
            parse_block(bad)


def test_scripted_fake_checks_sequence() -> None:
    t = ScriptedTransport([("A", None), ("B?", "1")])
    t.write("A")
    assert t.query("B?") == "1"
    assert t.done
    with pytest.raises(AssertionError, match="unexpected command 'C'"):
        t.write("C")
    t2 = ScriptedTransport([("A", None)])
    with pytest.raises(AssertionError, match="expected 'A', got 'Z'"):
        t2.write("Z")


def test_serial_transport_on_loopback() -> None:
    t = open_transport("loop://", name="stage", timeout_s=0.05)
    assert isinstance(t, SerialTransport)
    assert t.query("/1 1 get pos") == "/1 1 get pos"  # the loop echoes the line
    t.write("hello")
    assert t.read() == "hello"
    with pytest.raises(
        InstrumentTimeout, match=r"stage \(loop://\): no reply to 'read' within 0.05 s"
    ):
        t.read()
    t.close()


def test_factory_refuses_bad_arguments() -> None:
    with pytest.raises(InstrumentError, match="timeout must be > 0"):
        open_transport("loop://", name="x", timeout_s=0.0)
    with pytest.raises(InstrumentError, match="empty instrument resource"):
        open_transport("", name="x")


def test_serial_timeout_sets_pyserial_timeout_and_baud_rate_reaches_the_port() -> None:
    t = open_transport("loop://", name="stage", timeout_s=0.05, baud_rate=115200)
    assert isinstance(t, SerialTransport)
    port = t._port
    assert port.baudrate == 115200 and port.timeout == 0.05
    t.timeout_s = 0.3  # e.g. the generator's longer wait for *OPC?
    assert (port.timeout, port.write_timeout) == (0.3, 0.3)
    t.write("late line")
    t.clear()  # a late reply is dropped
    with pytest.raises(InstrumentTimeout):
        t.timeout_s = 0.01
        t.read()
    t.close()
