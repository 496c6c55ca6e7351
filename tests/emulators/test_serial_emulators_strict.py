"""The serial emulators are strict: the OFV-5000 echoes at power-up and both it and the Zaber
stage answer only at 115200 baud. The vibrometer driver on the OFV-5000 emulator: the command set
of the manual (VeloDec, Interface echo, MaxFreq, SignalDelay, AutoFocus Search/Found)."""

from __future__ import annotations

import pytest

from instruments.polytec import PolytecSettings, PolytecVibrometer
from sim_backend.emulators import PolytecEmulator, SimClock, SimTransport


def test_echoing_controller_is_read_correctly_and_echo_switched_off() -> None:
    emu = PolytecEmulator(range_name="VD-09 10mm/s/V")
    assert emu.echo
    vib = PolytecVibrometer(SimTransport(emu, "vibrometer", 1.0, SimClock()))
    assert vib.sensitivity_m_per_s_per_V() == pytest.approx(0.01)  # echoed line skipped
    assert vib.connect() == "OFV-5000 / OFV-534"
    assert not emu.echo and "Set,Interface,0,Echo,Off" in emu.commands
    vib.set_velocity_range("VD-09 50mm/s/V")
    assert emu.range_name == "VD-09 50mm/s/V"
    assert vib.signal_delay_s() == pytest.approx(7.3e-6)
    assert vib.autofocus(SimClock()) and emu.autofocus_count == 1
    assert vib.identity()["firmware"] == "2.4"


def test_decoder_number_from_the_bench_file() -> None:
    emu = PolytecEmulator(range_name="VD-09 10mm/s/V", decoder_index=0)
    table = {
        "decoder_name": "Get,VeloDec,0,Name",
        "range_get": "Get,VeloDec,0,Range",
        "range_set": "Set,VeloDec,0,Range,{value}",
        "max_frequency_get": "Get,VeloDec,0,MaxFreq",
        "signal_delay_get": "Get,VeloDec,0,SignalDelay",
    }
    vib = PolytecVibrometer(
        SimTransport(emu, "vibrometer", 1.0, SimClock()), PolytecSettings(commands=table)
    )
    vib.connect()
    vib.set_velocity_range("VD-09 5mm/s/V")
    assert emu.range_name == "VD-09 5mm/s/V"
    assert vib.bandwidth_Hz() == pytest.approx(500e3)


def test_serial_emulators_answer_only_at_their_baud_rate() -> None:
    from instruments.errors import InstrumentTimeout
    from instruments.zaber import ZaberSettings, ZaberStage
    from sim_backend.emulators import ZaberEmulator

    clock = SimClock()
    for_rate = {
        rate: ZaberStage(
            SimTransport(ZaberEmulator(clock), "stage", 1.0, clock, baud_rate=rate),
            ZaberSettings(model="X-LSM500A", clock=clock),
        )
        for rate in (9600, 115200)
    }
    with pytest.raises(InstrumentTimeout):
        for_rate[9600].connect()  # VISA's ASRL default: the stage hears garbage
    assert for_rate[115200].connect()["resolution"] == 64
    vib = PolytecVibrometer(SimTransport(PolytecEmulator(), "vib", 1.0, clock, baud_rate=9600))
    with pytest.raises(InstrumentTimeout):
        vib.connect()


def test_a_wrong_baud_rate_in_the_bench_file_fails_on_the_simulated_bench() -> None:
    from daq.connect import connect_bench
    from instruments.errors import InstrumentTimeout
    from protocols.bench import default_bench_path, parse_bench

    text = default_bench_path().read_text()
    text = text.replace("baud_rate: 115200              # Zaber", "baud_rate: 9600  # Zaber")
    with pytest.raises(InstrumentTimeout, match="stage"):
        connect_bench(parse_bench(text))


@pytest.mark.parametrize(
    ("command", "scope"),
    [
        (b"/1 0 get pos", "0"),
        (b"/1 0 home", "0"),
        (b"/1 0 stop", "0"),
        (b"/1 warnings", "0"),  # no axis field: the device
        (b"/1 0 07 get pos", "0"),  # with a message id
        (b"/1 1 get pos", "1"),
    ],
)
def test_zaber_reply_axis_is_the_command_scope(command: bytes, scope: str) -> None:
    """Zaber's manual: the reply's axis field is "the reply scope. 0 for the device or all
    axes, 1 onwards for an individual axis". The emulator answered a command to the device with
    its own axis number (``@01 1``), and ignored ``/1 warnings`` (no axis field)."""
    from sim_backend.emulators import ZaberEmulator

    reply = ZaberEmulator(SimClock()).handle(command)
    assert reply is not None and reply.split()[:2] == ["@01", scope]
