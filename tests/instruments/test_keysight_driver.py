"""Keysight driver on the scripted fake transport: exact commands, block bytes, errors, limits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from instruments.burst import Burst, burst_samples
from instruments.errors import InstrumentTimeout, LimitError, ReplyError
from instruments.interfaces import BurstConfig
from instruments.keysight import GeneratorLimits, KeysightGenerator, arb_peak_factor, dac_codes
from instruments.transport import ScriptedTransport

LIMITS = GeneratorLimits(max_piezo_V=150.0, amplifier_gain=20.0, max_amplitude_Vpp=10.0)
NO_ERR = ("SYST:ERR?", '+0,"No error"')
CFG = BurstConfig(Burst(8920.0, cycles=5.0), amplitude_Vpp=4.0, sample_rate_Hz=1.0e6)


def played_rate(n_points: int, config: BurstConfig = CFG) -> float:
    """The arb rate at which n points span the burst's window (point k at k / SRAT)."""
    return (n_points - 1) / config.shape.duration_s


def nr3(x: float) -> str:
    """A number as the 33500 answers it ("Typical Return" +1.000000000000000E+00)."""
    return f"{x:+.15E}"


def readback_script(
    ch: int, n_bytes: int, replies: dict[str, str] | None = None
) -> list[tuple[str, str]]:
    """The channel's answers to the driver's read-back queries, as the 33500 Series guide
    gives them (``replies`` overrides some, keyed by the query without ``SOURn:``)."""
    answers = {
        "FUNC?": "ARB",
        "FUNC:ARB?": f'"BIAFC{ch}"',
        "FUNC:ARB:SRAT?": nr3(played_rate(n_bytes // 2)),
        "FUNC:ARB:FILT?": "NORM",
        f"OUTP{ch}:LOAD?": "+9.9E+37",
        "VOLT:UNIT?": "VPP",
        "VOLT:LIM:HIGH?": nr3(5.0),
        "VOLT:LIM:LOW?": nr3(-5.0),
        "VOLT:LIM:STAT?": "1",
        "VOLT:OFFS?": nr3(0.0),
        "VOLT?": nr3(4.0),
        "BURS:MODE?": "TRIG",
        "BURS:NCYC?": nr3(1.0),
        "BURS:STAT?": "1",
        f"TRIG{ch}:SOUR?": "BUS",
        "OUTP:TRIG:SOUR?": f"CH{ch}",
        "OUTP:TRIG:SLOP?": "POS",
        "OUTP:TRIG?": "1",
        "FORM:BORD?": "SWAP",
    }
    answers.update(replies or {})
    prefixed = ("OUTP", "TRIG", "FORM")
    return [(q if q.startswith(prefixed) else f"SOUR{ch}:{q}", r) for q, r in answers.items()]


def config_script(ch: int, n_bytes: int) -> list[tuple[str, str | BaseException | None]]:
    head = f"#{len(str(n_bytes))}{n_bytes}"
    rate = played_rate(n_bytes // 2)
    return [
        (f"OUTP{ch} OFF", None),
        (f"SOUR{ch}:DATA:VOL:CLE", None),
        ("FORM:BORD SWAP", None),
        (f"SOUR{ch}:DATA:ARB:DAC BIAFC{ch},{head}<{n_bytes} bytes>", None),
        (f"SOUR{ch}:DATA:ATTR:POIN? BIAFC{ch}", f"+{n_bytes // 2}"),
        (f"SOUR{ch}:FUNC ARB", None),
        (f"SOUR{ch}:FUNC:ARB BIAFC{ch}", None),
        (f"SOUR{ch}:FUNC:ARB:FILT NORM", None),
        (f"SOUR{ch}:FUNC:ARB:SRAT {rate:.12g}", None),
        (f"SOUR{ch}:VOLT:LIM:STAT OFF", None),
        (f"OUTP{ch}:LOAD INF", None),
        (f"SOUR{ch}:VOLT:UNIT VPP", None),
        (f"SOUR{ch}:VOLT:LIM:HIGH 5", None),
        (f"SOUR{ch}:VOLT:LIM:LOW -5", None),
        (f"SOUR{ch}:VOLT:LIM:STAT ON", None),
        (f"SOUR{ch}:VOLT:OFFS 0", None),
        (f"SOUR{ch}:VOLT 4", None),
        (f"SOUR{ch}:BURS:MODE TRIG", None),
        (f"SOUR{ch}:BURS:NCYC 1", None),
        (f"TRIG{ch}:SOUR BUS", None),
        (f"SOUR{ch}:BURS:STAT ON", None),
        (f"OUTP:TRIG:SOUR CH{ch}", None),
        ("OUTP:TRIG:SLOP POS", None),
        ("OUTP:TRIG ON", None),
    ]


def test_configure_burst_exact_sequence_and_block_bytes() -> None:
    samples = burst_samples(CFG.shape, CFG.sample_rate_Hz)
    n_bytes = 2 * samples.size
    t = ScriptedTransport([*config_script(2, n_bytes), *readback_script(2, n_bytes), NO_ERR])
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
    script = [*config_script(1, 2 * samples.size), *readback_script(1, 2 * samples.size), NO_ERR]
    script += [("OUTP1 ON", None), NO_ERR, ("OUTP:TRIG:SOUR CH1", None)]
    script += [("*TRG", None), ("*OPC?", "1"), ("OUTP1?", "1"), ("OUTP2?", "0")]
    t = ScriptedTransport(script)
    gen = KeysightGenerator(t, LIMITS)
    gen.configure_burst(1, CFG)
    gen.output(1, True)
    gen.trigger()
    gen.wait_complete()
    snap = gen.snapshot()["channels"]
    assert t.done
    assert snap["1"]["output_on"] is True and snap["2"]["output_on"] is False


def test_the_snapshot_reads_the_outputs_and_never_claims_off_unread() -> None:
    """Before, the snapshot gave the state last asked for: after an unsafe end (the off never
    confirmed) the bench window listed both outputs "False". Now it asks ``OUTPn?``; a generator
    that does not answer gives ``None`` and the reason."""
    script = [("OUTP1?", "0"), ("OUTP2?", None), ("*OPC?", None)]
    gen = KeysightGenerator(ScriptedTransport(script), LIMITS)
    chans = gen.snapshot()["channels"]
    assert chans["1"] == {"output_on": False}
    assert chans["2"]["output_on"] is None and "OUTP2?" in chans["2"]["output_error"]


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


def test_unequal_peaks_are_checked_at_the_larger_reading_of_the_amplitude() -> None:
    """No Keysight text settles whether VOLT sets the DAC's full scale (+1 -> VOLT/2) or the arb
    data's own peak-to-peak; under the second, data from -0.5 to +1 peaks at 2/3 VOLT, not
    VOLT/2. The piezo limit was checked at VOLT/2 only: 7.2 Vpp passed a 75 V limit at gain
    20 (72 V under the first reading, 96 V under the second)."""
    assert arb_peak_factor(np.array([0.0, 1.0, -1.0, 0.0])) == 1.0
    assert arb_peak_factor(np.array([0.0, 1.0, -0.5, 0.0])) == pytest.approx(4 / 3)
    assert arb_peak_factor(np.array([0.0, 1.0, 0.5, 0.0])) == pytest.approx(2.0)
    assert arb_peak_factor(burst_samples(CFG.shape, 1e6)) == pytest.approx(1.088, abs=1e-3)
    wave = np.concatenate([np.zeros(4), np.linspace(-0.5, 1.0, 64), np.zeros(4)])
    limits = GeneratorLimits(max_piezo_V=75.0, amplifier_gain=20.0, max_amplitude_Vpp=10.0)
    cfg = BurstConfig(Burst(8920.0), amplitude_Vpp=7.2)
    t = ScriptedTransport([])
    with pytest.raises(LimitError, match=r"piezo 96 V .*peaks are unequal, .* x1\.333"):
        KeysightGenerator(t, limits).configure_waveform(1, wave, cfg)
    assert t.sent == [] and t.blocks == []


def test_an_external_trigger_is_refused_before_sending() -> None:
    """The guide: an external trigger source disables the trigger out, which starts the
    digitiser; the driver sent OUTP:TRIG ON beside it, read it back as 1, and every record
    would have waited for a trigger that never came."""
    t = ScriptedTransport([])
    cfg = BurstConfig(Burst(8920.0), amplitude_Vpp=1.0, trigger_source="external")
    with pytest.raises(LimitError, match="'external' turns off the trigger out"):
        KeysightGenerator(t, LIMITS).configure_burst(1, cfg)
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
    script = [*config_script(1, 2 * samples.size), *readback_script(1, 2 * samples.size)]
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


def test_snapshot_records_what_the_channel_reports_not_the_request() -> None:
    samples = burst_samples(CFG.shape, CFG.sample_rate_Hz)
    n_bytes = 2 * samples.size
    held = {"VOLT?": "+4.002000000000000E+00", "VOLT:OFFS?": "+5.000000000000000E-05"}
    t = ScriptedTransport(
        [
            *config_script(1, n_bytes),
            *readback_script(1, n_bytes, held),
            NO_ERR,
            ("OUTP1?", "0"),
            ("OUTP2?", "0"),
        ]
    )
    gen = KeysightGenerator(t, LIMITS)
    gen.configure_burst(1, CFG)  # within 0.1 % + 0.1 mV: accepted
    rb = gen.snapshot()["channels"]["1"]["read_back"]
    assert t.done
    assert rb["amplitude_Vpp"] == 4.002 and rb["offset_V"] == 5e-5  # not the 4 Vpp, 0 V asked
    assert rb["sample_rate_Hz"] == pytest.approx(played_rate(samples.size), rel=1e-15)
    assert rb["load_ohm"] == "INF" and rb["amplitude_unit"] == "VPP"
    assert (rb["arb_name"], rb["burst_cycles"], rb["trigger_source"]) == ("BIAFC1", 1, "BUS")
    assert rb["burst_on"] is True and rb["limit_on"] is True and rb["limit_high_V"] == 5.0


@pytest.mark.parametrize(
    ("query", "reply", "message"),
    [
        ("VOLT?", "+1.000000000000000E+01", "amplitude: requested 4 Vpp, read back 10 Vpp"),
        ("VOLT:OFFS?", "+2.000000000000000E-03", "offset: requested 0 V, read back 0.002 V"),
        ("BURS:NCYC?", "+2.000000000000000E+00", "burst count: requested 1 cycles, read back 2"),
        ("TRIG1:SOUR?", "IMM", "trigger source: requested BUS, read back IMM"),
        ("OUTP1:LOAD?", "+5.000000000000000E+01", "output load: requested INF ohm, read back 50"),
        ("FUNC:ARB?", '"EXP_RISE"', "arb waveform: requested BIAFC1, read back EXP_RISE"),
        ("BURS:STAT?", "0", "burst state: requested ON, read back OFF"),
        ("VOLT:UNIT?", "VRMS", "amplitude unit: requested VPP, read back VRMS"),
    ],
)
def test_a_coerced_setting_is_one_line_naming_setting_request_and_read_back(
    query: str, reply: str, message: str
) -> None:
    samples = burst_samples(CFG.shape, CFG.sample_rate_Hz)
    n_bytes = 2 * samples.size
    script = [*config_script(1, n_bytes), *readback_script(1, n_bytes, {query: reply}), NO_ERR]
    script += [("OUTP1 OFF", None), ("OUTP2 OFF", None), ("OUTP1?", "0"), ("OUTP2?", "0")]
    t = ScriptedTransport(script, name="generator (TCPIP::x::INSTR)")
    gen = KeysightGenerator(t, LIMITS)
    with pytest.raises(ReplyError) as info:
        gen.configure_burst(1, CFG)
    text = str(info.value)
    assert text.startswith("generator (TCPIP::x::INSTR): channel 1 ") and "\n" not in text
    assert message in text and "tolerance" in text
    assert gen.held(1) is None and "read_back" not in gen.snapshot()["channels"]["1"]
    assert t.done  # outputs switched off
    with pytest.raises(Exception, match="configure a burst"):
        gen.output(1, True)


def test_an_unreadable_read_back_reply_is_a_reply_error_naming_the_query() -> None:
    samples = burst_samples(CFG.shape, CFG.sample_rate_Hz)
    n_bytes = 2 * samples.size
    script = [*config_script(1, n_bytes), *readback_script(1, n_bytes, {"VOLT?": "garbage"})]
    t = ScriptedTransport([*script[: len(script) - 8], ("OUTP1 OFF", None), ("OUTP2 OFF", None)])
    with pytest.raises(ReplyError, match=r"amplitude: unreadable SOUR1:VOLT\? reply 'garbage'"):
        KeysightGenerator(t, LIMITS).configure_burst(1, CFG)
    assert t.done


@pytest.mark.parametrize(
    "reply", ['"BIAFC1"', '"VOLATILE:BIAFC1"', '"INT:\\\\BIAFC1.ARB"', '"biafc1.arb"']
)
def test_the_arb_name_reads_back_in_any_of_the_guides_forms(reply: str) -> None:
    """The FUNC:ARB? reply's exact form is not confirmed on an instrument; a file suffix or
    another case failed the configuration before."""
    from instruments.keysight_readback import _arb_name

    assert _arb_name("BIAFC1", reply.strip('"')) is None
    assert _arb_name("BIAFC1", "EXP_RISE") == "exact"
