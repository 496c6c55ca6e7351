"""The generator driver on the strict emulator and on a dying VISA link: late replies after a
timeout, a stale error queue at connect, dead links, and the carrier as the instrument plays it."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from instruments.burst import Burst
from instruments.errors import InstrumentError, InstrumentTimeout
from instruments.interfaces import BurstConfig
from instruments.keysight import GeneratorLimits, KeysightGenerator
from instruments.transport.visa import VisaTransport
from sim_backend.emulators import KeysightEmulator, SimClock, SimTransport

LIMITS = GeneratorLimits(max_piezo_V=150.0, amplifier_gain=20.0, max_amplitude_Vpp=10.0)


def on_emulator() -> tuple[KeysightGenerator, KeysightEmulator]:
    emu = KeysightEmulator()
    return KeysightGenerator(SimTransport(emu, "generator", 2.0, SimClock()), LIMITS), emu


def test_late_reply_after_a_timeout_is_never_read_as_the_next_answer() -> None:
    gen, emu = on_emulator()
    idn = gen.identify()
    emu.late_replies = 1  # the "1" of *OPC? arrives after its timeout
    with pytest.raises(InstrumentTimeout):
        gen.wait_complete()
    assert gen.identify() == idn  # the identity, not a stale "1"
    assert gen.errors() == []


def test_a_late_output_state_is_not_read_as_the_next_channels() -> None:
    """A second reader: ``OUTP1?`` answered late, and its "0" was read as channel 2's state on
    a network link, so the snapshot said off for an output that was on."""
    gen, emu = on_emulator()
    emu.channels[2].output_on = True
    emu.late_replies = 1
    chans = gen.snapshot()["channels"]
    assert chans["1"]["output_on"] is None and "OUTP1?" in chans["1"]["output_error"]
    assert chans["2"]["output_on"] is True
    assert gen.errors() == []


def test_a_line_left_unread_answers_the_next_query_on_a_network_link() -> None:
    """The transport double keeps what a network link keeps: a late reply waits in the output
    queue and answers the next query (only a serial line is flushed before each query)."""
    emu = KeysightEmulator()
    lan = SimTransport(emu, "generator", 2.0, SimClock())
    emu.late_replies = 1
    with pytest.raises(InstrumentTimeout):
        lan.query("*OPC?")
    assert lan.query("*IDN?") == "1"  # the late reply first
    assert lan.query("SYST:ERR?").count(",") == 3  # then the identity, still waiting
    assert lan.read().startswith("+0")


def test_connect_drops_a_reply_an_earlier_session_left_unread() -> None:
    """*CLS clears the error queue, not the output queue: a stale line would have answered
    *IDN? and shifted every answer after it."""
    emu = KeysightEmulator()
    earlier = SimTransport(emu, "generator", 2.0, SimClock())
    emu.late_replies = 1
    with pytest.raises(InstrumentTimeout):
        earlier.query("OUTP1?")  # the session crashes here; its "0" is still queued
    gen = KeysightGenerator(earlier, LIMITS)
    assert gen.connect().count(",") == 3
    assert gen.output_state(1) is False and gen.errors() == []


def test_connect_goes_on_where_the_session_has_no_device_clear() -> None:
    """pyvisa-py's USB and serial sessions answer a device clear with VI_ERROR_NSUP_OPER: the
    connect failed on them once it began with one (a second reader)."""
    emu = KeysightEmulator()
    link = SimTransport(emu, "generator", 2.0, SimClock())

    def unsupported() -> None:
        raise InstrumentError("generator: 'device clear' failed (VI_ERROR_NSUP_OPER)")

    link.clear = unsupported  # type: ignore[method-assign]
    assert KeysightGenerator(link, LIMITS).connect().count(",") == 3


def test_a_device_clear_that_times_out_ends_the_connect_at_once() -> None:
    """A dead link is said at the clear, not logged as "no device clear" and then met again
    at *IDN? after a second timeout (a reviewer)."""
    emu = KeysightEmulator()
    link = SimTransport(emu, "generator", 2.0, SimClock())

    def dead() -> None:
        raise InstrumentTimeout("generator: no reply to 'device clear' within 2 s")

    link.clear = dead  # type: ignore[method-assign]
    with pytest.raises(InstrumentTimeout, match="device clear"):
        KeysightGenerator(link, LIMITS).connect()
    assert emu.commands == []  # nothing sent after it


def test_connect_refuses_an_instrument_that_is_not_a_33500_or_33600(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A second reader: connect checked only that *IDN? had four fields, so a run configured
    and switched on whatever answered at generator.resource."""
    import sim_backend.emulators.keysight as emulated

    monkeypatch.setattr(emulated, "IDN", "TEKTRONIX,AFG31022,C012345,FV:1.5.2")
    gen, _ = on_emulator()
    with pytest.raises(InstrumentError, match="answers as TEKTRONIX AFG31022, not a Keysight"):
        gen.connect()


@pytest.mark.parametrize(
    "idn",
    [
        "Keysight Technologies,33622A,MY12345678,A.02.03-3.15-03-64-02",
        "Agilent Technologies,33522B,MY52800123,3.05-1.19-2.00-52-00",
        "Agilent Technologies,33509B,MY1,2.03-1.19-2.00-52-00",
        "Keysight Technologies,33500B,MY1,x",
    ],
)
def test_connect_takes_every_33500_and_33600_as_they_answer(
    idn: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    import sim_backend.emulators.keysight as emulated

    monkeypatch.setattr(emulated, "IDN", idn)
    gen, _ = on_emulator()
    assert gen.connect() == idn


def test_connect_clears_a_stale_error_queue() -> None:
    gen, emu = on_emulator()
    emu.push_error(-350, "Queue overflow")  # left over from the last session
    gen.connect()
    gen.configure_burst(1, BurstConfig(Burst(8920.0, cycles=5.0), amplitude_Vpp=1.0))
    assert emu.channels[1].function == "ARB"


@pytest.mark.parametrize("f_Hz", [8920.0, 6630.0, 12345.6])
@pytest.mark.parametrize("rate", [1.0e6, 250e3])
def test_carrier_as_played_is_the_protocols(f_Hz: float, rate: float) -> None:
    gen, emu = on_emulator()
    gen.configure_burst(
        2, BurstConfig(Burst(f_Hz, cycles=5.0), amplitude_Vpp=1.0, sample_rate_Hz=rate)
    )
    ch = emu.channels[2]
    x = np.asarray(ch.waveform)
    t = np.arange(x.size) / ch.sample_rate_Hz  # the instrument plays point k at k / SRAT
    # zero crossings of the carrier (the envelope is positive inside the window), from a
    # cubic spline through the points as played
    tc = CubicSpline(t, x).roots(extrapolate=False)
    T = t[-1]
    inner = np.unique(np.round(tc[(tc > 0.2 * T) & (tc < 0.8 * T)], 12))  # away from the tails
    played = (inner.size - 1) / (2.0 * (inner[-1] - inner[0]))
    assert abs(played / f_Hz - 1.0) < 2e-4, played


class DyingResource:
    """A pyvisa resource whose TCP link is gone (instrument off or unplugged)."""

    def __init__(self, exc: BaseException) -> None:
        self.exc = exc
        self.timeout = 0
        self.read_termination = self.write_termination = "\n"
        self.baud_rate = 9600

    def write(self, command: str) -> None:
        raise self.exc

    def query(self, command: str) -> str:
        raise self.exc

    def clear(self) -> None:
        raise self.exc


class Manager:
    def __init__(self, resource: Any) -> None:
        self.resource = resource

    def open_resource(self, name: str) -> Any:
        if isinstance(self.resource, BaseException):
            raise self.resource
        return self.resource


@pytest.mark.parametrize(
    "exc", [ConnectionRefusedError(111, "refused"), BrokenPipeError(32, "pipe")]
)
def test_dead_link_is_an_instrument_error_naming_instrument_resource_and_what_to_check(
    exc: BaseException,
) -> None:
    t = VisaTransport(
        "TCPIP0::10.0.0.5::INSTR", name="generator", resource_manager=Manager(DyingResource(exc))
    )
    gen = KeysightGenerator(t, LIMITS)
    with pytest.raises(InstrumentError) as info:
        gen.identify()
    msg = str(info.value)
    assert "generator (TCPIP0::10.0.0.5::INSTR)" in msg
    assert "check that the instrument is on" in msg and type(exc).__name__ in msg
    gen.safe_state()  # never raises


def test_visa_open_failure_and_asrl_baud_rate() -> None:
    with pytest.raises(
        InstrumentError, match=r"generator \(ASRL/dev/ttyS3::INSTR\): cannot open.*check"
    ):
        VisaTransport(
            "ASRL/dev/ttyS3::INSTR", name="generator", resource_manager=Manager(OSError("gone"))
        )
    res = DyingResource(OSError())
    VisaTransport(
        "ASRL3::INSTR", name="vibrometer", baud_rate=115200, resource_manager=Manager(res)
    )
    assert res.baud_rate == 115200  # VISA's own default is 9600


def test_identity_reports_the_output_load() -> None:
    gen, _ = on_emulator()
    gen.connect()
    assert gen.identity()["load_ohm"] == {"1": 50.0, "2": 50.0}  # the instrument's default
    gen.configure_burst(1, BurstConfig(Burst(8920.0, cycles=5.0), amplitude_Vpp=1.0))
    assert gen.identity()["load_ohm"]["1"] == float("inf")


def test_a_burst_longer_than_the_default_burst_period_configures_on_a_fresh_instrument() -> None:
    """The guide's BURSt Subsystem: under the immediate trigger of a fresh instrument, a burst
    longer than its 10 ms period raises the period and reports "Settings conflict". The driver
    switched the burst on before setting the bus trigger, so a 25 ms burst failed its first
    configuration; it now sets the trigger source first, as the guide orders them."""
    gen, emu = on_emulator()
    samples = np.sin(2 * np.pi * 1e3 * np.arange(25_000) / 1e6)  # 25 ms at 1 MSa/s
    cfg = BurstConfig(Burst(1e3, cycles=25), amplitude_Vpp=1.0, sample_rate_Hz=1e6)
    gen.configure_waveform(1, samples, cfg)
    assert emu.channels[1].trigger_source == "BUS" and gen.errors() == []


def test_an_offset_after_a_large_amplitude_is_not_clipped_by_the_old_amplitude() -> None:
    """Offset was set before amplitude: after a 9 Vpp burst, a 3 V offset with the old 9 Vpp
    reached 7.5 V, past the +/-5 V voltage limits (the guide: clipped, "Settings conflict"), and
    the legal 1 Vpp + 3 V was refused. Now the offset goes to 0 before the amplitude is set."""
    gen, emu = on_emulator()
    samples = np.sin(2 * np.pi * 8.92e3 * np.arange(3000) / 1e6)
    gen.configure_waveform(1, samples, BurstConfig(Burst(8.92e3, cycles=21), amplitude_Vpp=9.0))
    cfg = BurstConfig(Burst(8.92e3, cycles=21), amplitude_Vpp=1.0, offset_V=3.0)
    gen.configure_waveform(1, samples, cfg)
    assert (emu.channels[1].amplitude_Vpp, emu.channels[1].offset_V) == (1.0, 3.0)
