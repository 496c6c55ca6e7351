"""Polytec vibrometer driver: grammar, parsing, settings-driven property names."""

from __future__ import annotations

import pytest

from instruments.errors import InstrumentTimeout, LimitError, ReplyError, SignalLostError
from instruments.polytec import (
    PolytecSettings,
    PolytecVibrometer,
    parse_sensitivity,
    parse_si_value,
)
from instruments.transport import ScriptedTransport


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("VD-09 10mm/s/V", 0.01),
        ("VD-09 1 mm/s/V", 1e-3),
        ("50um/s/V", 50e-6),
        ("VD-06 1m/s/V", 1.0),
    ],
)
def test_sensitivity_parsed_from_range(name: str, value: float) -> None:
    assert parse_sensitivity(name) == pytest.approx(value)


def test_bad_range_and_values() -> None:
    with pytest.raises(ReplyError, match="cannot read a sensitivity"):
        parse_sensitivity("VD-09 fast")
    assert parse_si_value("100kHz", "Hz") == pytest.approx(1e5)
    assert parse_si_value("7.3 us", "s") == pytest.approx(7.3e-6)
    with pytest.raises(ReplyError):
        parse_si_value("lots", "Hz")


def test_connect_identify_range_set_and_readback() -> None:
    t = ScriptedTransport(
        [
            ("Set,Interface,0,Echo,Off", None),
            ("Get,Interface,0,Echo", "Off"),
            ("Get,Controller,0,Name", "OFV-5000"),
            ("Get,SensorHead,0,Name", "OFV-534"),
            ("Get,Controller,0,Version", "2.4"),
            ("Get,VeloDec,1,Name", "VD-09"),
            ("Set,VeloDec,1,Range,5mm/s/V", None),
            ("Get,VeloDec,1,Range", "5mm/s/V"),
            ("Get,VeloDec,1,Range", "5mm/s/V"),
        ]
    )
    v = PolytecVibrometer(t)
    assert v.connect() == "OFV-5000 / OFV-534"
    v.set_velocity_range("VD-09 5mm/s/V")
    assert v.sensitivity_m_per_s_per_V() == pytest.approx(5e-3)
    assert t.done


def test_command_table_entries_are_overridable() -> None:
    s = PolytecSettings(commands={"signal_delay_get": "Get,VeloDec,0,SignalDelay"})
    t = ScriptedTransport([("Get,VeloDec,0,SignalDelay", "12 us")])
    assert PolytecVibrometer(t, s).signal_delay_s() == pytest.approx(12e-6)
    with pytest.raises(LimitError, match="unknown entries \\['range'\\]"):
        PolytecSettings(commands={"range": "Get,X,0,Range"})


def test_wrong_decoder_and_failed_readback_are_refused() -> None:
    t = ScriptedTransport(
        [
            ("Get,VeloDec,1,Name", "VD-08"),
            ("Get,VeloDec,1,Name", "VD-09"),
            ("Set,VeloDec,1,Range,2mm/s/V", None),
            ("Get,VeloDec,1,Range", "5mm/s/V"),
        ]
    )
    v = PolytecVibrometer(t)
    with pytest.raises(ReplyError, match=r"asks for decoder VD-09.*'VD-08'"):
        v.set_velocity_range("VD-09 10mm/s/V")
    with pytest.raises(ReplyError, match="reads back '5mm/s/V'"):
        v.set_velocity_range("VD-09 2mm/s/V")


def test_signal_level_and_loss() -> None:
    t = ScriptedTransport([("Get,SignalLevel,0,Value", "85"), ("Get,SignalLevel,0,Value", "3")])
    v = PolytecVibrometer(t)
    assert v.check_signal() == pytest.approx(0.85)
    with pytest.raises(SignalLostError, match=r"signal level 0\.03 below 0\.20"):
        v.check_signal()


def test_errors_and_timeouts() -> None:
    t = ScriptedTransport(
        [("Get,VeloDec,1,Range", "Not Available"), ("Get,SignalLevel,0,Value", None)],
        name="vibrometer",
    )
    v = PolytecVibrometer(t)
    with pytest.raises(ReplyError, match="answered 'Not Available'"):
        v.sensitivity_m_per_s_per_V()
    with pytest.raises(
        InstrumentTimeout, match="vibrometer: no reply to 'Get,SignalLevel,0,Value'"
    ):
        v.signal_level()
    with pytest.raises(ReplyError):
        v.set_velocity_range("nonsense")  # refused before sending
    assert t.done


def test_controller_without_an_echo_setting_connects() -> None:
    t = ScriptedTransport(
        [
            ("Get,Controller,0,Name", "OFV-5000"),
            ("Get,SensorHead,0,Name", "OFV-534"),
            ("Get,Controller,0,Version", "Not Available"),
        ]
    )
    v = PolytecVibrometer(t, PolytecSettings(commands={"echo_set": None}))
    assert v.connect() == "OFV-5000 / OFV-534"  # no Set,Interface,... sent; no firmware
    assert t.done and v._firmware is None


def test_a_level_above_the_full_scale_is_refused_not_clipped() -> None:
    """The signal level's scale is not in Polytec's public command list. Before, a reading above
    ``level_full_scale`` was clipped to 1, so on a controller whose scale is larger every level
    read as full and no point ever saw a lost signal; the bench file could not even set it."""
    t = ScriptedTransport(
        [("Get,SignalLevel,0,Value", "620"), ("Get,SignalLevel,0,Value", "620")],
        name="vibrometer",
    )
    with pytest.raises(
        ReplyError,
        match=r"vibrometer: signal level 620 is above the full scale 100 "
        r"\(vibrometer\.level_full_scale in the bench file\)",
    ):
        PolytecVibrometer(t).check_signal()
    assert PolytecVibrometer(t, PolytecSettings(level_full_scale=775)).check_signal() == (
        pytest.approx(0.8)
    )
    assert t.done


def test_the_velocity_ranges_are_the_decoders_own() -> None:
    """The VD-09's ranges as an OFV-5000 lists them (5 mm/s/V to 1 m/s/V, and "LP" low-pass
    variants from 20 mm/s/V); before, the table gave it the VD-08's 1 and 2 mm/s/V and refused
    200 mm/s/V to 1 m/s/V, and a controller left on "50mm/s/V LP" could not be read."""
    from instruments.polytec import range_max_frequency_Hz, velocity_range_error

    for good in ("VD-09 5mm/s/V", "VD-09 200mm/s/V", "VD-09 1m/s/V", "VD-09 50mm/s/V LP"):
        assert velocity_range_error(good) is None, good
    for bad in ("VD-09 1mm/s/V", "VD-09 2mm/s/V", "VD-09 10mm/s/V LP", "VD-08 5mm/s/V LP"):
        assert velocity_range_error(bad) is not None, bad
    assert velocity_range_error("VD-08 0.5mm/s/V") is None
    assert parse_sensitivity("VD-09 50mm/s/V LP") == pytest.approx(0.05)
    assert parse_sensitivity("1m/s/V LP") == pytest.approx(1.0)
    assert range_max_frequency_Hz("VD-09 50mm/s/V LP") is None  # the filter's corner: unknown
    t = ScriptedTransport(
        [
            ("Get,VeloDec,1,Name", "VD-09"),
            ("Set,VeloDec,1,Range,50mm/s/V LP", None),
            ("Get,VeloDec,1,Range", "50mm/s/V LP"),
            ("Get,VeloDec,1,Range", "50mm/s/V LP"),
        ]
    )
    v = PolytecVibrometer(t)
    v.set_velocity_range("VD-09 50mm/s/V LP")
    assert v.sensitivity_m_per_s_per_V() == pytest.approx(0.05)
