"""Polytec vibrometer driver: grammar, parsing, settings-driven property names."""

from __future__ import annotations

import pytest

from instruments.errors import InstrumentTimeout, ReplyError, SignalLostError
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


def test_identify_range_set_and_readback() -> None:
    t = ScriptedTransport(
        [
            ("GetDevInfo,Controller,0,Name", "OFV-5000"),
            ("GetDevInfo,SensorHead,0,Name", "OFV-534"),
            ("Set,VelocityDecoder,0,Range,VD-09 5mm/s/V", None),
            ("Get,VelocityDecoder,0,Range", "VD-09 5mm/s/V"),
            ("Get,VelocityDecoder,0,Range", "VD-09 5mm/s/V"),
        ]
    )
    v = PolytecVibrometer(t)
    assert v.identify() == "OFV-5000 / OFV-534"
    v.set_velocity_range("VD-09 5mm/s/V")
    assert v.sensitivity_m_per_s_per_V() == pytest.approx(5e-3)
    assert t.done


def test_property_names_are_settings() -> None:
    s = PolytecSettings(decoder_device="VD-09", decoder_index=1, delay_property="Delay")
    t = ScriptedTransport([("Get,VD-09,1,Delay", "12us")])
    assert PolytecVibrometer(t, s).signal_delay_s() == pytest.approx(12e-6)


def test_signal_level_and_loss() -> None:
    t = ScriptedTransport(
        [("Get,SensorHead,0,SignalLevel", "85"), ("Get,SensorHead,0,SignalLevel", "3")]
    )
    v = PolytecVibrometer(t)
    assert v.check_signal() == pytest.approx(0.85)
    with pytest.raises(SignalLostError, match=r"signal level 0\.03 below 0\.20"):
        v.check_signal()


def test_errors_and_timeouts() -> None:
    t = ScriptedTransport(
        [("Get,VelocityDecoder,0,Range", "Error: unknown"), ("Get,SensorHead,0,SignalLevel", None)],
        name="vibrometer",
    )
    v = PolytecVibrometer(t)
    with pytest.raises(ReplyError, match="answered 'Error: unknown'"):
        v.velocity_range()
    with pytest.raises(
        InstrumentTimeout, match="vibrometer: no reply to 'Get,SensorHead,0,SignalLevel'"
    ):
        v.signal_level()
    with pytest.raises(ReplyError):
        v.set_velocity_range("nonsense")  # refused before sending
    assert t.done
