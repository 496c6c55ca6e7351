"""The vibrometer driver on the strict OFV-5000 emulator: echo on at power-up, the command set
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
