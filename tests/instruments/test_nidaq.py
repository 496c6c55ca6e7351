"""The NI digitiser against a stand-in ``nidaqmx`` (tests/instruments/standin_nidaqmx) that keeps
NI-DAQmx's task states, its error codes, its rate coercion and its reference-trigger rule; and,
on the lab PC only, against a card."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import pytest

from instruments.errors import (
    DriverNotInstalledError,
    InstrumentError,
    InstrumentTimeout,
    LimitError,
)
from instruments.interfaces import AcquisitionConfig, Digitiser

from .standin_nidaqmx import Card, DeviceSpec, install
from .standin_nidaqmx.constants import TerminalConfiguration
from .standin_nidaqmx.task import State

TRIGGER = "/Dev1/PFI0"


@pytest.fixture()
def card(monkeypatch: pytest.MonkeyPatch) -> Card:
    c = Card()
    install(monkeypatch, c)
    return c


def digitiser(card: Card, **kw: Any) -> Any:
    from daq.digitiser_nidaq import NidaqDigitiser

    return NidaqDigitiser("Dev1", clock=card, **kw)


def config(**kw: Any) -> AcquisitionConfig:
    base: dict[str, Any] = {
        "sample_rate_Hz": 100e3,
        "n_samples": 1000,
        "n_pretrigger": 0,
        "trigger_source": TRIGGER,
        "timeout_s": 2.0,
    }
    return AcquisitionConfig(**{**base, **kw})


def task_of(card: Card) -> Any:
    (task,) = card.tasks
    return task


def test_a_trigger_timeout_is_reported_and_the_retry_acquires(card: Card) -> None:
    dig = digitiser(card)
    assert isinstance(dig, Digitiser)
    dig.configure(config())
    dig.arm()
    with pytest.raises(InstrumentTimeout) as info:
        dig.read()  # the generator never fired
    dig.arm()  # the engine's retry
    assert card.fire(TRIGGER) == 1
    rec = dig.read()
    assert rec.velocity_V.shape == (1000,) and rec.n_pretrigger == 0
    assert rec.reference_V[0] == 1.0  # the record starts at the trigger
    msg = str(info.value)
    assert "Dev1" in msg and TRIGGER in msg and "-200284" in msg and "\n" not in msg


def test_the_task_is_committed_once_and_cycles_between_committed_and_running(card: Card) -> None:
    dig = digitiser(card)
    dig.configure(config())
    task = task_of(card)
    assert task.state is State.COMMITTED  # channel, rate and trigger errors show in configure()
    for fire in (False, True, True):
        dig.arm()
        assert task.state is State.RUNNING
        if fire:
            card.fire(TRIGGER)
            dig.read()
        else:
            with pytest.raises(InstrumentTimeout):
                dig.read()
        assert task_of(card) is task and task.state is State.COMMITTED


def test_reference_trigger_arm_returns_once_the_pretrigger_is_acquired(card: Card) -> None:
    dig = digitiser(card)
    rate = dig.configure(config(sample_rate_Hz=10e3, n_samples=600, n_pretrigger=100))
    t0 = card.now()
    dig.arm()
    assert card.now() - t0 >= 100 / rate  # the device holds 100 samples before the trigger
    assert card.fire(TRIGGER) == 1  # the generator fires right after arm(): not ignored
    rec = dig.read()
    assert rec.n_pretrigger == 100
    step = int(np.argmax(rec.reference_V > 0.5))
    assert step == 100  # the trigger falls after exactly the pretrigger samples
    np.testing.assert_allclose(rec.time_s * 1e3, rec.velocity_V, atol=1e-9)


def test_the_rate_ceiling_is_per_channel_and_the_coerced_rate_is_returned(card: Card) -> None:
    card.devices["Dev1"] = DeviceSpec(ai_max_single_chan_rate=2e6, ai_max_multi_chan_rate=1e6)
    dig = digitiser(card, max_rate_Hz=2e6)  # the bench allows 2 MS/s per channel
    # the card's aggregate 1 MS/s is shared by the two channels: 500 kS/s each
    with pytest.raises(LimitError, match=r"600000 S/s per channel is above 500000 S/s"):
        dig.configure(config(sample_rate_Hz=600e3))
    assert not card.tasks
    assert dig.max_rate_per_channel_Hz() == pytest.approx(500e3)
    rate = dig.configure(config(sample_rate_Hz=450e3))
    assert rate == pytest.approx(100e6 / 222)  # timebase / floor(timebase / rate): 450.45 kS/s
    assert dig.snapshot()["sample_rate_Hz"] == rate
    tight = digitiser(card, max_rate_Hz=200e3)  # the bench's own ceiling wins when lower
    with pytest.raises(LimitError, match=r"daq\.max_rate"):
        tight.configure(config(sample_rate_Hz=300e3))


@pytest.mark.parametrize(
    ("name", "member"),
    [
        ("RSE", TerminalConfiguration.RSE),
        ("NRSE", TerminalConfiguration.NRSE),
        ("differential", TerminalConfiguration.DIFF),
    ],
)
def test_terminal_configuration_reaches_both_channels(card: Card, name: str, member: Any) -> None:
    dig = digitiser(card, terminal_config=name)
    dig.configure(config())
    assert [ch.terminal_config for ch in task_of(card)._chans] == [member, member]
    assert dig.snapshot()["terminal_config"] == name


def test_an_unsupported_terminal_configuration_is_one_line_naming_it(card: Card) -> None:
    dig = digitiser(card, terminal_config="pseudodifferential")  # not on this card
    with pytest.raises(InstrumentError) as info:
        dig.configure(config())
    msg = str(info.value)
    assert "pseudodifferential" in msg and "Dev1 (PCIe-6361)" in msg and "-200077" in msg
    assert "\n" not in msg and not card.tasks  # the refused task was cleared
    with pytest.raises(LimitError, match="'single-ended' is not one of"):
        digitiser(card, terminal_config="single-ended")


def test_daq_errors_name_the_device_the_channel_and_what_to_check(card: Card) -> None:
    from daq.digitiser_nidaq import NidaqDigitiser

    with pytest.raises(InstrumentError, match=r"no device Dev9: check daq\.device"):
        NidaqDigitiser("Dev9", clock=card)
    dig = digitiser(card)
    with pytest.raises(InstrumentError) as info:
        dig.configure(config(reference_channel="Dev1/ai99"))
    msg = str(info.value)
    assert "Dev1/ai99" in msg and "daq.reference_channel" in msg and "-200170" in msg
    assert "\n" not in msg


def test_a_task_nidaqmx_cannot_create_is_one_line_naming_the_device(card: Card) -> None:
    """``nidaqmx.Task()`` raises a DaqError when the driver cannot make a task; before, that
    escaped ``configure`` raw (a traceback from the run) instead of an InstrumentError."""
    dig = digitiser(card)
    card.refuse_new_tasks = ("Resource requested by this task has already been reserved.", -50103)
    with pytest.raises(InstrumentError, match=r"NI-DAQ Dev1: cannot create a task: .*-50103"):
        dig.configure(config())
    card.refuse_new_tasks = None
    assert dig.configure(config()) == pytest.approx(100e3)


def test_a_cleared_task_is_never_used_again(card: Card) -> None:
    dig = digitiser(card)
    dig.configure(config())
    dig.arm()
    task_of(card).close()  # another program (or a device reset) cleared it
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a second clear would warn (DaqResourceWarning)
        with pytest.raises(InstrumentError, match="configure again"):
            dig.read()
        dig.safe_state()
        dig.close()
    with pytest.raises(InstrumentError, match="configure before arming"):
        dig.arm()


def test_safe_state_twice_and_reconfigure(card: Card) -> None:
    dig = digitiser(card)
    dig.configure(config())
    dig.arm()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        dig.safe_state()
        dig.safe_state()
    assert not card.tasks
    dig.configure(config(n_pretrigger=10))
    dig.arm()
    card.fire(TRIGGER)
    assert dig.read().n_pretrigger == 10


def test_the_bench_file_sets_terminal_config_and_rate_ceiling(
    card: Card, monkeypatch: pytest.MonkeyPatch
) -> None:
    """daq.terminal_config and daq.max_rate of a lab bench file reach the NI digitiser."""
    import instruments.transport
    from daq.connect import connect_bench
    from protocols.bench import default_bench_path, parse_bench
    from sim_backend.simbench import SimWorld, SimWorldConfig

    world = SimWorld(SimWorldConfig())  # instruments on the other end of the (fake) cables
    monkeypatch.setattr(
        instruments.transport, "open_transport", lambda r, *, name, **k: world.transport(name)
    )
    text = (default_bench_path().parent / "lab_bench.yaml").read_text()
    assert "terminal_config: differential" in text
    text = text.replace("terminal_config: differential", "terminal_config: RSE")
    assert "max_rate: 500 kS/s" in text
    text = text.replace("max_rate: 500 kS/s", "max_rate: 250 kS/s")
    bench = connect_bench(parse_bench(text))
    dig = bench.digitiser
    assert dig.snapshot()["terminal_config"] == "RSE"
    assert dig.max_rate_per_channel_Hz() == pytest.approx(250e3)
    dig.configure(config())
    assert {ch.terminal_config for ch in task_of(card)._chans} == {TerminalConfiguration.RSE}
    bench.close()
    assert not card.tasks


def _driver_present() -> bool:
    from daq.digitiser_nidaq import _load_nidaqmx

    try:
        _load_nidaqmx()
    except DriverNotInstalledError:
        return False
    return True


def test_missing_driver_is_one_clear_error() -> None:
    if _driver_present():
        pytest.skip("NI-DAQmx driver installed on this machine")
    from daq.digitiser_nidaq import NidaqDigitiser

    with pytest.raises(DriverNotInstalledError, match="NI-DAQmx driver not installed"):
        NidaqDigitiser("Dev1")


@pytest.mark.hardware
def test_hardware_acquisition() -> None:
    from daq.digitiser_nidaq import NidaqDigitiser

    dig = NidaqDigitiser("Dev1")
    rate = dig.configure(
        AcquisitionConfig(sample_rate_Hz=100e3, n_samples=1000, n_pretrigger=100, timeout_s=5.0)
    )
    assert rate > 0
    dig.safe_state()


def test_a_task_left_holding_the_card_blocks_the_next_until_the_safe_state(card: Card) -> None:
    """A second reader: the stand-in reserved nothing, so two digitisers on Dev1 both ran; on a
    real card a task left committed (a leak) makes the next one's commit fail with -50103.
    The driver says so in one line, and its safe state frees the card."""
    first = digitiser(card)
    first.configure(config())  # committed, never closed
    second = digitiser(card)
    with pytest.raises(InstrumentError) as info:
        second.configure(config())
    assert "-50103" in str(info.value) and "\n" not in str(info.value)
    first.safe_state()  # closes its task: the card is free
    assert second.configure(config()) == pytest.approx(100e3)
