"""``KeysightGenerator.output_state`` reads ``OUTPn?`` from the emulated 33500B: the engine's
confirmation of the safe state (issue 15)."""

from __future__ import annotations

import pytest

from instruments.errors import InstrumentTimeout, ReplyError
from instruments.keysight import GeneratorLimits, KeysightGenerator
from sim_backend.emulators import KeysightEmulator, SimClock, SimTransport


def _gen() -> tuple[KeysightGenerator, KeysightEmulator]:
    emu = KeysightEmulator()
    limits = GeneratorLimits(max_piezo_V=150.0, amplifier_gain=20.0, max_amplitude_Vpp=10.0)
    return KeysightGenerator(SimTransport(emu, "generator", 2.0, SimClock()), limits), emu


def test_output_state_reads_the_instrument_not_the_driver() -> None:
    gen, _ = _gen()
    assert gen.output_state(1) is False
    gen.transport.write("OUTP1 ON")  # behind the driver's back
    assert gen.output_state(1) is True
    gen.safe_state()
    assert gen.output_state(1) is False and gen.output_state(2) is False


def test_a_silent_generator_cannot_confirm_its_outputs() -> None:
    gen, emu = _gen()
    emu.responsive = False
    with pytest.raises(InstrumentTimeout):
        gen.output_state(1)


def test_a_strange_reply_is_not_taken_for_off(monkeypatch: pytest.MonkeyPatch) -> None:
    gen, _ = _gen()
    monkeypatch.setattr(gen.transport, "query", lambda cmd: "+9.9E+37")
    with pytest.raises(ReplyError):
        gen.output_state(1)
