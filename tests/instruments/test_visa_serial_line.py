"""A late reply on a serial line over the real pyvisa-py (an ``ASRL`` resource on a pseudo
terminal): it must not answer the next query. The far end is written here from the OFV-5000's
RS-232 description (one reply line per ``Get``, ``\\n``-terminated), not from the driver.

Before, ``VisaTransport.query`` sent and read without discarding what waited on the line (the
pyserial transport did): after one timeout every reply came one query late, so
``velocity_range()`` read the signal level (``'512 VD-09'``)."""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from instruments.errors import InstrumentError, InstrumentTimeout
from instruments.interfaces import Transport
from instruments.polytec import PolytecVibrometer
from instruments.transport import open_transport

from .pty_line import serve_lines

pytestmark = pytest.mark.skipif(
    sys.platform == "win32" or not hasattr(os, "openpty"), reason="needs a pseudo terminal"
)

REPLIES = {
    b"Get,VeloDec,1,Name": b"VD-09\n",
    b"Get,VeloDec,1,Range": b"50mm/s/V\n",
    b"Get,VeloDec,1,SignalDelay": b"7.3 \xb5s\n",  # the micro sign as one Latin-1 byte
    b"Get,VeloDec,1,MaxFreq": "2.5 MHz \u00b5\n".encode(),  # and as UTF-8 (a made-up reply)
}
LATE_S = 0.8  # the signal level's reply comes after the driver's 0.5 s timeout


def _controller(line: bytes) -> bytes | None:
    """The OFV-5000's answer to ``line``; the signal level's comes late."""
    if line == b"Get,SignalLevel,0,Value":
        time.sleep(LATE_S)
        return b"512\n"
    return REPLIES.get(line)


@contextmanager
def controller_line(kind: str = "visa") -> Iterator[Transport]:
    """The transport to the far end on a pseudo terminal: a VISA ``ASRL`` resource on
    pyvisa-py (``"visa"``) or the port itself on pyserial (``"pyserial"``)."""
    pytest.importorskip("pyvisa_py")
    import tty

    far, near = os.openpty()
    tty.setraw(near)
    stop = threading.Event()
    thread = threading.Thread(target=serve_lines, args=(far, _controller, stop), daemon=True)
    thread.start()
    port = os.ttyname(near)
    resource = f"ASRL{port}::INSTR" if kind == "visa" else port
    transport = open_transport(resource, name="vibrometer", timeout_s=0.5, baud_rate=115200)
    try:
        yield transport
    finally:
        stop.set()
        thread.join(2)
        transport.close()
        os.close(far)
        os.close(near)


def test_a_late_reply_on_a_visa_serial_line_does_not_answer_the_next_query() -> None:
    with controller_line() as transport:
        vib = PolytecVibrometer(transport)
        with pytest.raises(InstrumentTimeout):
            vib.signal_level()
        time.sleep(LATE_S)  # the late "512" now waits on the line
        assert vib.velocity_range() == "VD-09 50mm/s/V"
        assert vib.velocity_range() == "VD-09 50mm/s/V"


@pytest.mark.parametrize("kind", ["visa", "pyserial"])
def test_a_micro_sign_in_a_reply_reads_on_both_transports(kind: str) -> None:
    """PLACE's OFV-5000 driver met a micro sign in a reply in the lab; both transports decoded
    replies as strict ASCII, so the vibrometer's snapshot (its signal delay) failed."""
    with controller_line(kind) as transport:
        vib = PolytecVibrometer(transport)
        assert vib.signal_delay_s() == pytest.approx(7.3e-6)
        assert transport.query("Get,VeloDec,1,MaxFreq") == "2.5 MHz \u00b5"


@pytest.mark.skipif(sys.platform == "win32", reason="ASRL3 is COM3 there")
def test_an_asrl_number_off_windows_names_the_port_form_that_works() -> None:
    """pyvisa-py turns ``ASRL3::INSTR`` into COM3 on Windows only; elsewhere it tried a port
    named "3" and the error said only to check the cable."""
    pytest.importorskip("pyvisa_py")
    with pytest.raises(InstrumentError, match=r"ASRL/dev/ttyUSB0::INSTR, or just /dev/ttyUSB0"):
        open_transport("ASRL3::INSTR", name="vibrometer", timeout_s=0.5)


def test_a_usb_resource_without_pyusb_says_what_to_install_or_use() -> None:
    pytest.importorskip("pyvisa_py")
    try:
        import usb  # noqa: F401
    except ImportError:
        pass
    else:
        pytest.skip("pyusb is installed here")
    with pytest.raises(InstrumentError, match=r"pip install pyusb\); or set visa_backend: '@ivi'"):
        open_transport("USB0::0x0957::0x2807::MY57000001::INSTR", name="generator")
