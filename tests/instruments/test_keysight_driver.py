"""Keysight driver on the scripted fake transport: exact commands, block bytes, errors, limits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from instruments.burst import Burst, burst_samples
from instruments.errors import InstrumentTimeout, LimitError, ReplyError
from instruments.interfaces import BurstConfig
from instruments.keysight import GeneratorLimits, KeysightGenerator, dac_codes
from instruments.transport import ScriptedTransport

LIMITS = GeneratorLimits(max_piezo_V=150.0, amplifier_gain=20.0, max_amplitude_Vpp=10.0)
NO_ERR = ("SYST:ERR?", '+0,"No error"')
CFG = BurstConfig(Burst(8920.0, cycles=5.0), amplitude_Vpp=4.0, sample_rate_Hz=1.0e6)


def played_rate(n_points: int, config: BurstConfig = CFG) -> float:
    """The arb rate at which n points span the burst's window (point k at k / SRAT)."""
    return (n_points - 1) / config.shape.duration_s


def srat_readback(ch: int, n_bytes: int) -> tuple[str, str]:
    return (f"SOUR{ch}:FUNC:ARB:SRAT?", f"{played_rate(n_bytes // 2):+.9E}")


def config_script(ch: int, n_bytes: int) -> list[tuple[str, str | BaseException | None]]:
    head = f"#{len(str(n_bytes))}{n_bytes}"
    rate = played_rate(n_bytes // 2)
    return [
        (f"OUTP{ch} OFF", None),
        (f"SOUR{ch}:DATA:VOL:CLE", None),
        ("FORM:BORD SWAP", None),
        (f"SOUR{ch}:DATA:ARB:DAC BIAFC{ch},{head}<{n_bytes} bytes>", None),
        (f"SOUR{ch}:FUNC ARB", None),
        (f"SOUR{ch}:FUNC:ARB BIAFC{ch}", None),
        (f"SOUR{ch}:FUNC:ARB:SRAT {rate:.12g}", None),
        (f"OUTP{ch}:LOAD INF", None),
        (f"SOUR{ch}:VOLT:LIM:HIGH 5", None),
        (f"SOUR{ch}:VOLT:LIM:LOW -5", None),
        (f"SOUR{ch}:VOLT:LIM:STAT ON", None),
        (f"SOUR{ch}:VOLT:OFFS 0", None),
        (f"SOUR{ch}:VOLT 4", None),
        (f"SOUR{ch}:BURS:MODE TRIG", None),
        (f"SOUR{ch}:BURS:NCYC 1", None),
        (f"SOUR{ch}:BURS:STAT ON", None),
        (f"TRIG{ch}:SOUR BUS", None),
        (f"OUTP:TRIG:SOUR CH{ch}", None),
        ("OUTP:TRIG:SLOP POS", None),
        ("OUTP:TRIG ON", None),
    ]


def test_configure_burst_exact_sequence_and_block_bytes() -> None:
    samples = burst_samples(CFG.shape, CFG.sample_rate_Hz)
    n_bytes = 2 * samples.size
    t = ScriptedTransport([*config_script(2, n_bytes), NO_ERR, srat_readback(2, n_bytes)])
    gen = KeysightGenerator(t, LIMITS)
    gen.configure_burst(2, CFG)
    assert t.done
    header, data = t.blocks[0]
    assert header == "SOUR2:DATA:ARB:DAC BIAFC2,"
    codes = np.frombuffer(data, dtype="<i2")  # FORM:BORD SWAP: little-endian
    assert codes.size == samples.size
    assert codes[0] == 0 and codes[-1] == 0
    assert codes.max() <= 32767 and codes.max() >= 32700
    assert np.array_equal(codes, np.rint(samples * 32767).astype(np.int16))
    assert data[:4] == codes[:2].astype("<i2").tobytes()


def test_output_trigger_and_opc() -> None:
    samples = burst_samples(CFG.shape, CFG.sample_rate_Hz)
    script = [*config_script(1, 2 * samples.size), NO_ERR, srat_readback(1, 2 * samples.size)]
    script += [("OUTP1 ON", None), NO_ERR, ("OUTP:TRIG:SOUR CH1", None)]
    script += [("*TRG", None), ("*OPC?", "1")]
    t = ScriptedTransport(script)
    gen = KeysightGenerator(t, LIMITS)
    gen.configure_burst(1, CFG)
    gen.output(1, True)
    gen.trigger()
    gen.wait_complete()
    assert t.done
    assert gen.snapshot()["channels"]["1"]["output_on"] is True


def test_output_on_refused_before_configuration() -> None:
    t = ScriptedTransport([])
    with pytest.raises(Exception, match="configure a burst on channel 1"):
        KeysightGenerator(t, LIMITS).output(1, True)
    assert t.sent == []


@pytest.mark.parametrize(
    ("config", "pattern"),
    [
        (
            BurstConfig(Burst(8920.0), amplitude_Vpp=12.0),
            r"12 Vpp .*exceeds the generator maximum 10 Vpp",
        ),
        (
            BurstConfig(Burst(8920.0), amplitude_Vpp=8.0),
            r"piezo 80 V.*exceeds the piezo limit 150 V",
        ),
    ],
)
def test_limits_refused_before_sending(config: BurstConfig, pattern: str) -> None:
    limits = GeneratorLimits(
        max_piezo_V=150.0 if "12" in pattern else 50.0, amplifier_gain=20.0, max_amplitude_Vpp=10.0
    )
    pattern = pattern.replace("150 V", f"{limits.max_piezo_V:g} V")
    t = ScriptedTransport([])
    with pytest.raises(LimitError, match=pattern):
        KeysightGenerator(t, limits).configure_burst(1, config)
    assert t.sent == [] and t.blocks == []


def test_nan_waveform_refused_before_sending() -> None:
    wave = np.zeros(64)
    wave[10] = math.nan
    t = ScriptedTransport([])
    with pytest.raises(LimitError, match="sample 10 is not finite"):
        KeysightGenerator(t, LIMITS).configure_waveform(1, wave, CFG)
    assert t.sent == []
    with pytest.raises(LimitError, match="normalised"):
        dac_codes(np.full(16, 1.5))


def test_error_after_configuration_raises_and_leaves_outputs_off() -> None:
    samples = burst_samples(CFG.shape, CFG.sample_rate_Hz)
    script = [*config_script(1, 2 * samples.size)]
    script += [("SYST:ERR?", '-222,"Data out of range"'), NO_ERR]
    script += [("OUTP1 OFF", None), ("OUTP2 OFF", None)]
    t = ScriptedTransport(script)
    gen = KeysightGenerator(t, LIMITS)
    with pytest.raises(ReplyError, match="configuring channel 1: -222,Data out of range"):
        gen.configure_burst(1, CFG)
    assert t.done
    with pytest.raises(Exception, match="configure a burst"):
        gen.output(1, True)  # the failed configuration is not armed


def test_malformed_replies_are_clear_errors() -> None:
    t = ScriptedTransport([("*IDN?", "garbage"), ("SYST:ERR?", "what?"), ("*OPC?", "0")])
    gen = KeysightGenerator(t, LIMITS)
    with pytest.raises(ReplyError, match=r"malformed \*IDN\? reply 'garbage'"):
        gen.identify()
    with pytest.raises(ReplyError, match="malformed SYST:ERR"):
        gen.errors()
    with pytest.raises(ReplyError, match=r"unexpected \*OPC\? reply"):
        gen.wait_complete()


def test_no_reply_times_out_naming_command_and_safe_state_never_raises() -> None:
    t = ScriptedTransport([("*OPC?", None), ("*OPC?", "1")], name="generator (TCPIP::x::INSTR)")
    gen = KeysightGenerator(t, LIMITS)
    with pytest.raises(
        InstrumentTimeout, match=r"generator \(TCPIP::x::INSTR\): no reply to '\*OPC\?'"
    ):
        gen.wait_complete(timeout_s=3.0)
    assert t.timeout_s == 1.0  # restored
    dead = ScriptedTransport([("OUTP1 OFF", InstrumentTimeout("dead")), ("OUTP2 OFF", None)])
    KeysightGenerator(dead, LIMITS).safe_state()
    assert dead.done


def test_limits_dataclass_validates() -> None:
    with pytest.raises(LimitError, match="amplifier_gain must be > 0"):
        GeneratorLimits(max_piezo_V=100.0, amplifier_gain=0.0)
    assert LIMITS.max_generator_peak_V == pytest.approx(5.0)
    assert GeneratorLimits(
        max_piezo_V=40.0, amplifier_gain=20.0
    ).max_generator_peak_V == pytest.approx(2.0)
