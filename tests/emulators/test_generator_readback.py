"""The generator's settings read back from the emulated 33500B, the emulator answering as the
33500 Series Operating and Service Guide says, and a strict emulator that coerces values: the
driver reports what the channel holds, or a one-line mismatch, never the request."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from instruments.burst import Burst, burst_samples
from instruments.errors import ReplyError
from instruments.interfaces import BurstConfig
from instruments.keysight import GeneratorLimits, KeysightGenerator
from sim_backend.emulators import KeysightEmulator, SimClock, SimTransport

LIMITS = GeneratorLimits(max_piezo_V=150.0, amplifier_gain=20.0, max_amplitude_Vpp=10.0)


def on(emu: KeysightEmulator, limits: GeneratorLimits = LIMITS) -> KeysightGenerator:
    return KeysightGenerator(SimTransport(emu, "generator (simulated)", 2.0, SimClock()), limits)


def burst(amplitude_Vpp: float, **kw: float) -> BurstConfig:
    return BurstConfig(Burst(8920.0), amplitude_Vpp=amplitude_Vpp, **kw)  # type: ignore[arg-type]


def test_emulator_answers_queries_as_the_guide_gives_them() -> None:
    emu = KeysightEmulator()
    t = on(emu).transport
    q, w = t.query, t.write
    assert q("OUTP1:LOAD?") == "+5.000000000000000E+01"  # default 50 ohm
    w("SOUR1:VOLT 4")
    w("OUTP1:LOAD INF")  # 50 ohm -> high Z doubles the displayed amplitude, no error
    assert q("SOUR1:VOLT?") == "+8.000000000000000E+00"
    assert q("OUTP1:LOAD?") == "+9.9E+37" and q("SOUR1:VOLT:UNIT?") == "VPP"
    w("SOUR1:BURS:NCYC 3")
    assert q("SOUR1:BURS:NCYC?") == "+3.000000000000000E+00"
    assert q("SOUR1:BURS:STAT?") == "0" and q("SOUR1:BURS:MODE?") == "TRIG"
    w("OUTP:TRIG:SLOP NEG")
    assert q("OUTP:TRIG:SLOP?") == "NEG" and q("TRIG1:SOUR?") == "IMM"
    w("SOUR1:VOLT:LIM:STAT ON")
    w("OUTP1:LOAD 50")  # not while the limits are on
    assert q("OUTP1:LOAD?") == "+9.9E+37"
    assert q("SYST:ERR?") == '-221,"Settings conflict"'
    # past the limits (+/-5 V here) a level is clipped to them, and a conflict reported
    w("SOUR1:VOLT:LIM:HIGH 2")
    w("SOUR1:VOLT:LIM:LOW -2")
    w("SOUR1:VOLT 6")  # 3 V peak: clipped to 4 Vpp
    assert q("SOUR1:VOLT?") == "+4.000000000000000E+00"
    assert q("SYST:ERR?").startswith("-221,")


def test_read_back_is_what_the_snapshot_records() -> None:
    emu = KeysightEmulator()
    gen = on(emu)
    gen.configure_burst(2, burst(4.0, offset_V=0.1))
    rb = gen.snapshot()["channels"]["2"]["read_back"]
    ch = emu.channels[2]
    assert rb["amplitude_Vpp"] == ch.amplitude_Vpp == 4.0 and rb["offset_V"] == 0.1
    assert rb["sample_rate_Hz"] == ch.sample_rate_Hz and rb["load_ohm"] == "INF"
    assert rb["trigger_out_source"] == "CH2" and rb["burst_cycles"] == 1


def test_strict_emulator_rounding_is_recorded_not_the_request() -> None:
    emu = KeysightEmulator(strict=True)  # amplitude kept to 4 digits
    gen = on(emu)
    gen.configure_burst(1, burst(1.23456))
    assert emu.channels[1].amplitude_Vpp == 1.235
    assert gen.snapshot()["channels"]["1"]["read_back"]["amplitude_Vpp"] == 1.235


def test_strict_emulator_clipping_the_amplitude_is_reported_not_recorded() -> None:
    emu = KeysightEmulator(strict=True)
    # limits looser than the instrument (the driver's own refuses below 2 mVpp up front)
    gen = on(emu, dataclasses.replace(LIMITS, min_amplitude_Vpp=1e-4))
    with pytest.raises(ReplyError) as info:  # 0.5 mVpp is below 2 mVpp at high Z: clipped
        gen.configure_burst(1, burst(0.0005))
    assert str(info.value) == (
        "generator (simulated): channel 1 amplitude: requested 0.0005 Vpp, read back 0.002 Vpp "
        "(tolerance 0.1 % + 0.1 mV); instrument errors: -222,Data out of range"
    )
    assert not any(c.output_on for c in emu.channels.values())
    assert "read_back" not in gen.snapshot()["channels"]["1"]


def test_strict_emulator_quantising_the_sample_rate_is_reported() -> None:
    emu = KeysightEmulator(strict=True, srat_digits=4)  # silently, no SCPI error
    gen = on(emu)
    with pytest.raises(ReplyError, match=r"channel 1 arb sample rate: requested 99988\d\.\d+ Sa/s, "
                       r"read back 999900 Sa/s \(tolerance 1e-6 relative\)$"):  # fmt: skip
        gen.configure_burst(1, burst(1.0))
    assert gen.held(1) is None


def test_a_channel_configured_twice_turns_its_limits_off_before_the_load() -> None:
    emu = KeysightEmulator()  # refuses a load change while the voltage limits are on
    gen = on(emu)
    gen.configure_burst(1, burst(1.0))
    gen.configure_burst(1, burst(2.0))  # the limits are on from the first one
    held = gen.held(1)
    assert held is not None and held.amplitude_Vpp == 2.0 and math.isinf(held.load_ohm)
    assert held.limit_on and gen.errors() == []


def test_an_arb_filter_left_at_step_is_set_back_and_read_back() -> None:
    """FUNC:ARB:FILT (NORMal, STEP or OFF) was neither set nor read: a channel left at STEP by
    another program played the burst as a staircase, and OFF lowers the 33500's arb rate
    ceiling to 62.5 MSa/s. It is now set to NORMal, the default, and read back."""
    emu = KeysightEmulator()
    emu.channels[1].arb_filter = "STEP"
    gen = on(emu)
    gen.configure_burst(1, burst(2.0))
    assert emu.channels[1].arb_filter == "NORM"
    held = gen.held(1)
    assert held is not None and held.arb_filter == "NORM"


def test_clearing_the_volatile_memory_reloads_the_default_arb() -> None:
    """DATA:VOL:CLE "clears waveform memory for the specified channel and reloads the default
    waveform" (the guide): the emulator kept the cleared burst selected and playing, so a
    configuration that failed after the clear would have found the old burst still there."""
    emu = KeysightEmulator()
    gen = on(emu)
    gen.configure_burst(1, burst(2.0))
    q, w = gen.transport.query, gen.transport.write
    played = emu.channels[1].waveform.copy()
    assert q("SOUR1:FUNC:ARB?") == '"BIAFC1"'
    w("SOUR1:DATA:VOL:CLE")
    assert q("SOUR1:FUNC:ARB?") == '"INT:\\BUILTIN\\EXP_RISE.ARB"'
    now = emu.channels[1].waveform
    assert now.size != played.size or not (now == played).all()
    assert q("SYST:ERR?") == '+0,"No error"'
    w("SOUR1:FUNC:ARB BIAFC1")  # gone with the clear
    assert q("SYST:ERR?").startswith("-224,")
    gen.configure_burst(1, burst(2.0))  # the driver's own order uploads it again
    assert (emu.channels[1].waveform == played).all() and gen.errors() == []


def test_the_emulator_answers_the_points_stored_under_an_arb_name() -> None:
    """DATA:ATTRibute:POINts? "Returns the number of points in the specified arbitrary waveform
    segment" (33500B programming reference): the points stored under that name, the selected
    arb's without one; an unknown name is refused as FUNC:ARB refuses it."""
    emu = KeysightEmulator()
    t = on(emu).transport
    t.write("FORM:BORD SWAP")
    t.write_block("SOUR2:DATA:ARB:DAC RAMP16,", np.arange(16, dtype="<i2").tobytes())
    assert t.query("SOUR2:DATA:ATTR:POIN? RAMP16") == "+16"
    assert t.query('SOUR2:DATA:ATTRibute:POINts? "ramp16"') == "+16"
    assert t.query("SOUR2:DATA:ATTR:POIN?") == f"{emu.channels[2].waveform.size:+d}"
    t.write("SOUR1:DATA:ATTR:POIN? RAMP16")  # channel 1's memory does not hold it
    assert t.query("SYST:ERR?").startswith("-224,")


def test_the_strict_emulator_holds_every_point_of_the_upload() -> None:
    """The points stored are read back after the upload (none was read: a truncated upload
    would have played a wrong burst); on the strict emulator a normal upload passes."""
    emu = KeysightEmulator(strict=True)
    gen = on(emu)
    gen.configure_burst(1, burst(2.0))
    stored = emu.volatile[1]["BIAFC1"].size
    i = emu.commands.index("SOUR1:DATA:ATTR:POIN? BIAFC1")
    assert emu.commands[i - 1].startswith("SOUR1:DATA:ARB:DAC BIAFC1,")
    assert stored == emu.channels[1].waveform.size and gen.errors() == []


def test_a_truncated_upload_is_refused_before_any_burst_is_armed() -> None:
    """An upload the generator stored short (here its first 100 points) is one line naming the
    waveform, the points sent and the points stored; nothing after it is sent but the safe
    state, so no burst is selected, armed or played."""
    emu = KeysightEmulator(strict=True)
    emu.stored_points = 100
    gen = on(emu)
    with pytest.raises(ReplyError) as info:
        gen.configure_burst(1, burst(2.0))
    i = emu.commands.index("SOUR1:DATA:ATTR:POIN? BIAFC1")
    n = burst_samples(burst(2.0).shape, burst(2.0).sample_rate_Hz).size
    assert str(info.value) == (
        f"generator (simulated): channel 1 arb waveform BIAFC1: sent {n} points, stored 100"
    )
    after = emu.commands[i + 1 :]
    assert not any("FUNC" in c or "BURS" in c or "TRG" in c for c in after), after
    ch = emu.channels[1]
    assert ch.function != "ARB" and not ch.burst_on and not ch.output_on
    assert gen.held(1) is None and emu.n_triggers == 0
