"""The SCPI generator driver through the real pyvisa path, on a pyvisa-sim YAML instrument."""

from __future__ import annotations

from pathlib import Path

import pytest

from instruments.errors import InstrumentError
from instruments.keysight import GeneratorLimits, KeysightGenerator
from instruments.transport import open_transport

YAML = Path(__file__).with_name("keysight_sim.yaml")
RESOURCE = "TCPIP::10.0.0.5::INSTR"


@pytest.fixture()
def generator() -> KeysightGenerator:
    t = open_transport(RESOURCE, name="generator", timeout_s=0.5, visa_backend=f"{YAML}@sim")
    return KeysightGenerator(t, GeneratorLimits(max_piezo_V=150.0, amplifier_gain=20.0))


def test_identity_through_pyvisa(generator: KeysightGenerator) -> None:
    assert generator.identify().startswith("Keysight Technologies,33522B")
    generator.wait_complete()


def test_error_queue_through_pyvisa(generator: KeysightGenerator) -> None:
    assert generator.errors() == []
    generator.transport.write("BOGUS:COMMAND 1")
    assert generator.errors() == ["-113,Undefined header"]
    assert generator.errors() == []


def test_terminations_and_safe_state(generator: KeysightGenerator) -> None:
    generator.safe_state()  # the sim device knows OUTPn OFF: no error queued
    assert generator.errors() == []
    assert generator.transport.query("*IDN?").endswith("58-00")  # termination stripped


def test_unknown_resource_is_a_clear_error() -> None:
    # pyvisa-sim opens any address but nothing answers there: the identity check refuses it
    t = open_transport(
        "TCPIP::10.9.9.9::INSTR", name="generator", timeout_s=0.2, visa_backend=f"{YAML}@sim"
    )
    gen = KeysightGenerator(t, GeneratorLimits(max_piezo_V=150.0, amplifier_gain=20.0))
    with pytest.raises(InstrumentError, match=r"generator \(TCPIP::10.9.9.9::INSTR\)"):
        with pytest.warns(UserWarning):
            gen.identify()
    with pytest.raises(InstrumentError, match=r"stage \(no-such-port\): cannot open serial port"):
        open_transport("no-such-port", name="stage")
    with pytest.raises(InstrumentError, match="empty instrument resource"):
        open_transport("  ", name="vibrometer")


def test_a_visa_library_that_is_not_installed_is_said_in_one_line_with_what_to_do() -> None:
    """A second reader: pyvisa's message holds line breaks, the command line shows the first
    line only, and "VISA backend '@ivi' not available (Could not open VISA library:" was all a
    physicist read, without the reason or what to do."""
    from instruments.errors import DriverNotInstalledError
    from instruments.transport.visa import VisaTransport

    class NoLibrary:
        def __call__(self, backend: str) -> None:
            raise OSError("Could not open VISA library:\n  no library found at ...\n")

    import pyvisa

    real = pyvisa.ResourceManager
    pyvisa.ResourceManager = NoLibrary()  # type: ignore[misc,assignment]
    try:
        with pytest.raises(DriverNotInstalledError) as caught:
            VisaTransport("TCPIP::10.0.0.9::INSTR", name="generator", backend="@ivi")
    finally:
        pyvisa.ResourceManager = real  # type: ignore[misc]
    text = str(caught.value)
    assert "\n" not in text and "no library found" in text
    assert "install the NI-VISA or Keysight IO Libraries" in text
