"""Every real driver end-to-end on its wire-level emulator through SimTransport, with faults."""

from __future__ import annotations

import numpy as np
import pytest

from instruments.burst import Burst, burst_samples
from instruments.errors import (
    InstrumentTimeout,
    MoveTimeout,
    NotHomedError,
    ReplyError,
    SignalLostError,
    StallError,
)
from instruments.interfaces import BurstConfig, FunctionGenerator, Stage, Vibrometer
from instruments.keysight import GeneratorLimits, KeysightGenerator
from instruments.polytec import PolytecVibrometer
from instruments.zaber import ZaberSettings, ZaberStage
from sim_backend.emulators import (
    KeysightEmulator,
    PolytecEmulator,
    SimClock,
    SimTransport,
    ZaberEmulator,
)

LIMITS = GeneratorLimits(max_piezo_V=150.0, amplifier_gain=20.0, max_amplitude_Vpp=10.0)
CFG = BurstConfig(Burst(8920.0, cycles=5.0), amplitude_Vpp=4.0, sample_rate_Hz=1.0e6, offset_V=0.1)


@pytest.fixture()
def clock() -> SimClock:
    return SimClock()


def make_generator(clock: SimClock) -> tuple[KeysightGenerator, KeysightEmulator]:
    emu = KeysightEmulator()
    return KeysightGenerator(SimTransport(emu, "generator", 2.0, clock), LIMITS), emu


def test_generator_state_and_trigger_hook(clock: SimClock) -> None:
    gen, emu = make_generator(clock)
    assert isinstance(gen, FunctionGenerator)
    fired: list[tuple[int, ...]] = []
    emu.trigger_hooks.append(fired.append)
    gen.identify()
    gen.configure_burst(2, CFG)
    ch = emu.channels[2]
    assert not ch.output_on
    expected = np.rint(burst_samples(CFG.shape, CFG.sample_rate_Hz) * 32767) / 32767
    np.testing.assert_allclose(ch.waveform, expected, atol=1e-12)
    played = (expected.size - 1) / CFG.shape.duration_s  # n points span the window T
    assert ch.sample_rate_Hz == pytest.approx(played, rel=1e-9)
    assert (ch.amplitude_Vpp, ch.offset_V) == (4.0, 0.1)
    assert ch.load_ohm == np.inf and ch.burst_on and ch.burst_cycles == 1
    assert ch.trigger_source == "BUS" and emu.trigger_out_on and emu.trigger_out_source == 2
    gen.output(2, True)
    assert ch.output_on
    gen.trigger()
    gen.wait_complete()
    assert fired == [(2,)]
    gen.safe_state()
    assert not any(c.output_on for c in emu.channels.values())
    assert gen.errors() == []


def test_emulator_rejects_bad_scpi_with_real_codes(clock: SimClock) -> None:
    gen, emu = make_generator(clock)
    t = gen.transport
    t.write("SOUR1:VOLT 30")  # over the 20 Vpp high-Z maximum (load is 50 Ohm by default: 10)
    t.write("NOPE:NOPE 1")
    t.write("SOUR1:FUNC:ARB MISSING")
    t.write_block("SOUR1:DATA:ARB:DAC X,", b"\x00")
    assert gen.errors() == [
        "-222,Data out of range",
        "-113,Undefined header",
        "-224,Illegal parameter value;waveform not in volatile memory",
        "-161,Invalid block data",
    ]
    for _ in range(25):
        emu.push_error(-100, "Command error")
    errs = gen.errors()
    assert len(errs) == 20 and errs[-1] == "-350,Queue overflow"


def test_generator_error_injection_and_silence(clock: SimClock) -> None:
    gen, emu = make_generator(clock)
    emu.push_error(-310, "System error")
    with pytest.raises(ReplyError, match="-310,System error"):
        gen.configure_burst(1, CFG)
    assert not emu.channels[1].output_on
    emu.responsive = False
    t0 = clock.now()
    with pytest.raises(InstrumentTimeout, match=r"generator: no reply to '\*OPC\?' within 2 s"):
        gen.wait_complete()
    assert clock.now() == pytest.approx(t0 + 4.0)  # the query, then *OPC? after a device clear
    gen.safe_state()  # dead link: logs, does not raise


def test_vibrometer_on_emulator(clock: SimClock) -> None:
    emu = PolytecEmulator()
    vib = PolytecVibrometer(SimTransport(emu, "vibrometer", 1.0, clock))
    assert isinstance(vib, Vibrometer)
    vib.set_velocity_range("VD-09 50mm/s/V")
    assert emu.range_name == "VD-09 50mm/s/V"
    snap = vib.snapshot()
    assert snap["sensitivity_m_per_s_per_V"] == pytest.approx(0.05)
    assert snap["signal_delay_s"] == pytest.approx(7.3e-6)
    assert snap["bandwidth_Hz"] == pytest.approx(2.5e6)  # the VD-09's MaxFreq at 50mm/s/V
    assert snap["identity"] == "OFV-5000 / OFV-534"
    emu.signal_level = 0.5
    assert vib.check_signal() == pytest.approx(0.5)
    emu.lose_signal()
    with pytest.raises(SignalLostError):
        vib.check_signal()
    with pytest.raises(ReplyError, match="reads back"):
        vib.set_velocity_range("VD-09 3mm/s/V")  # not a range of this decoder
    assert vib.autofocus() and emu.autofocus_count == 1


def make_stage(clock: SimClock, **kw: object) -> tuple[ZaberStage, ZaberEmulator]:
    emu = ZaberEmulator(clock, travel_m=(0.0, 0.3), model="X-LSM200A")
    s = ZaberSettings(clock=clock, soft_limits_m=(0.005, 0.25), microstep_m=0.047625e-6, **kw)  # type: ignore[arg-type]
    return ZaberStage(SimTransport(emu, "stage", 1.0, clock), s), emu


def test_stage_moves_take_simulated_time(clock: SimClock) -> None:
    stage, emu = make_stage(clock)
    assert isinstance(stage, Stage)
    assert not stage.is_homed()
    with pytest.raises(NotHomedError):
        stage.move_to(0.1)
    stage.home()
    assert stage.is_homed() and emu.homed
    t0 = clock.now()
    stage.move_to(0.1)
    assert emu.position_m() == pytest.approx(0.1, abs=1e-6)
    assert clock.now() - t0 == pytest.approx(0.1 / 0.025 + 0.2, abs=0.1)  # travel + settle
    stage.move_to(0.05)  # from above: overshoots below, approaches upwards
    assert any(c.startswith("/1 1 ") and " move abs " in c for c in emu.commands)
    assert stage.position() == pytest.approx(0.05, abs=1e-6)
    assert stage.speed() == pytest.approx(0.025, rel=1e-3)


def test_stage_faults(clock: SimClock) -> None:
    stage, emu = make_stage(clock)
    stage.home()
    emu.stall()
    with pytest.raises(StallError, match="stalled"):
        stage.move_to(0.1)
    stage.clear_warnings()
    with pytest.raises(NotHomedError):  # a stall may have slipped the position: home again
        stage.move_to(0.1)
    stage.home()
    stage.move_to(0.1)
    emu.lose_homing()
    with pytest.raises(NotHomedError):
        stage.move_to(0.2)
    emu.responsive = False
    with pytest.raises(InstrumentTimeout, match="stage: no reply"):
        stage.position()
    stage.safe_state()


@pytest.mark.parametrize("firmware", [7, 6])
def test_stage_connects_on_firmware_7_and_6(clock: SimClock, firmware: int) -> None:
    """Firmware 7 names the id ``device.id`` and has no ``deviceid``: before, connect sent only
    ``get deviceid`` and a current X-LSM refused it (reported as "stage not homed")."""
    emu = ZaberEmulator(clock, firmware=firmware)
    settings = ZaberSettings(clock=clock, model="X-LSM500A")
    stage = ZaberStage(SimTransport(emu, "stage", 1.0, clock), settings)
    identity = stage.connect()
    assert identity["device_id"] == emu.device_id
    assert identity["firmware"] == ("7.29" if firmware == 7 else "6.28")


def test_stage_addressed_to_the_device_takes_the_device_scope_replies(clock: SimClock) -> None:
    """A stage configured with axis 0 (the device) sends every command at device scope, and a
    real device answers those with axis 0 (the manual's reply scope): the driver takes them,
    none refused as from another axis. The emulator answered with axis 1 before."""
    emu = ZaberEmulator(clock, model="X-LSM500A")
    settings = ZaberSettings(clock=clock, model="X-LSM500A", axis=0)
    stage = ZaberStage(SimTransport(emu, "stage", 1.0, clock), settings)
    stage.connect()
    stage.home()
    stage.move_to(0.1)
    stage.safe_state()
    assert stage.position() == pytest.approx(0.1, abs=1e-6) and stage.is_homed()
    assert emu.commands and all(c.startswith("/1 0 ") for c in emu.commands)


def test_a_higher_warning_does_not_hide_the_missing_reference(clock: SimClock) -> None:
    """A reply shows only the flag of highest priority: a supply-voltage warning (WV) hid WR,
    and an unhomed stage read as homed (the run then skipped homing and moved)."""
    stage, emu = make_stage(clock)
    emu.raise_flag("WV")
    assert emu.flag == "WV" and "WR" in emu.flags
    assert not stage.is_homed()
    with pytest.raises(NotHomedError):
        stage.move_to(0.1)
    stage.home()
    assert stage.is_homed()


def test_every_fault_flag_is_a_fault_and_a_rejection_keeps_its_reason(clock: SimClock) -> None:
    """FD (driver disabled) passed as OK before; a rejection while WR showed was reported as
    "not homed" whatever its reason."""
    stage, emu = make_stage(clock)
    with pytest.raises(ReplyError, match=r"get nothing' rejected \(BADCOMMAND, warning WR"):
        stage.command("get nothing")
    stage.home()
    emu.raise_flag("FD")
    with pytest.raises(StallError, match=r"driver disabled \(FD\)"):
        stage.position()


def test_a_stall_left_from_before_is_cleared_at_connect_and_the_stage_homed(
    clock: SimClock,
) -> None:
    """FS persists until ``warnings clear`` (homing does not clear it): before, every reply
    raised, so the next run could not even connect; now connect clears it, logs it, and the
    stage is homed again before it moves."""
    stage, emu = make_stage(clock)
    stage.home()
    emu.stall()
    emu.handle(b"/1 1 home")
    assert "FS" in emu.flags  # the manual: only 'warnings clear' clears it
    fresh = ZaberStage(stage.transport, stage.settings)
    fresh.connect()
    assert "FS" not in emu.flags and not fresh.is_homed()  # homed, but homed again first
    fresh.home()
    fresh.move_to(0.1)
    assert emu.position_m() == pytest.approx(0.1, abs=1e-6)


def test_homing_at_a_slow_approach_speed_is_waited_for(clock: SimClock) -> None:
    """The device homes at the lesser of maxspeed and limit.approach.maxspeed: at 1 mm/s from
    the middle of 300 mm that is 150 s, and the driver gave up after a fixed 120 s (then
    stopped the axis, and the run could not start)."""
    stage, emu = make_stage(clock)
    emu.approach_maxspeed = round(1e-3 / emu.microstep_m * 1.6384)  # 1 mm/s
    t0 = clock.now()
    stage.home()
    assert stage.is_homed() and clock.now() - t0 == pytest.approx(150, abs=1)


def test_homing_shows_wr_until_it_ends_and_a_cancel_stops_it(clock: SimClock) -> None:
    """The manual's example: WR shows while the home move runs (the emulator cleared it as the
    command arrived). ``home(cancel)`` stops the axis at the next poll and returns, not homed."""
    import threading

    stage, emu = make_stage(clock)
    emu.approach_maxspeed = round(1e-3 / emu.microstep_m * 1.6384)  # 1 mm/s: 150 s to home

    class AfterPolls(threading.Event):
        def __init__(self, n: int) -> None:
            super().__init__()
            self.n = n

        def is_set(self) -> bool:
            self.n -= 1
            return self.n < 0

    stage.home(cancel=AfterPolls(3))
    assert emu.busy() and "NI" in emu.flags  # decelerating after the stop; it interrupted
    stage.safe_state()  # waits for the axis to come to rest
    assert not emu.busy() and not emu.homed and "WR" in emu.flags
    assert not stage.is_homed() and clock.now() < 10  # stopped within a few polls
    emu.handle(b"/1 1 home")
    assert emu.busy() and emu.flag == "WR"
    stage.home()
    assert emu.homed and stage.is_homed()


def test_stop_decelerates_busy_and_safe_state_waits_for_rest(clock: SimClock) -> None:
    """The manual: "All movement commands, including stop, put the axis into the BUSY state,
    while they are being executed"; NI flags a move that another command interrupted. The
    emulator stopped the axis dead and answered IDLE, and the driver's safe state returned
    at once: a stage still decelerating read as safe."""
    stage, emu = make_stage(clock)
    stage.home()
    stage.command(f"move abs {round(0.2 / emu.microstep_m)}")  # 25 mm/s, not waited for
    clock.sleep(1.0)
    here = emu.position_m()
    reply = stage.transport.query("/1 1 stop")
    assert " OK BUSY NI " in reply  # decelerating; the move was interrupted
    v, a = 0.025, emu.accel_m_per_s2
    t0 = clock.now()
    stage.safe_state()
    assert not emu.busy() and not stage.is_moving()
    assert clock.now() - t0 == pytest.approx(v / a, abs=0.06)  # polled every 50 ms
    assert emu.position_m() - here == pytest.approx(v * v / (2 * a), abs=1e-6)
    assert stage.is_homed()  # a stopped move keeps the reference


def test_a_stage_still_moving_after_the_bound_or_silent_is_said_so(
    clock: SimClock, caplog: pytest.LogCaptureFixture
) -> None:
    """The safe state's wait is bounded (stop_timeout_s); an axis still decelerating after it
    reads as moving. A stage that did not answer its stop is not asked again (a second
    timeout would hold up the end of the run): is_moving raises at once."""
    stage, emu = make_stage(clock, stop_timeout_s=1.0)
    stage.home()
    emu.accel_m_per_s2 = 1e-3  # 12.5 s to stop from 25 mm/s
    stage.command(f"move abs {round(0.2 / emu.microstep_m)}")
    clock.sleep(1.0)
    t0 = clock.now()
    stage.safe_state()
    assert 1.0 <= clock.now() - t0 <= 1.1
    assert stage.is_moving() and "still moving" in caplog.text
    emu.responsive = False
    stage.safe_state()
    sent = len(emu.commands)
    with pytest.raises(InstrumentTimeout, match="no reply to 'stop'"):
        stage.is_moving()
    t0 = clock.now()
    stage.safe_state()  # closing, or the next caller: not another whole timeout
    assert len(emu.commands) == sent and clock.now() == t0  # nothing sent: the link is dead
    emu.responsive = True  # once a command is answered again, it is asked as before
    clock.sleep(15.0)  # the 12.5 s deceleration is over
    assert stage.position() >= 0 and not stage.is_moving()


def test_a_stop_after_the_homing_ended_keeps_the_reference(clock: SimClock) -> None:
    """The home move ends, then a stop arrives before any status request: the emulator kept
    WR (no reference) for ever, as if the homing had been cut short."""
    _, emu = make_stage(clock)
    emu.handle(b"/1 1 home")
    clock.sleep(60.0)
    emu.handle(b"/1 1 stop")
    assert emu.homed and "WR" not in emu.flags


def test_a_stage_whose_replies_carry_checksums_is_refused_in_one_line(clock: SimClock) -> None:
    """``comm.checksum 1`` ends every reply in ``:CC``; the driver read '0:4F' as the data and
    failed on it as a malformed number, naming nothing that would help."""
    stage, emu = make_stage(clock)
    emu.checksum = True
    with pytest.raises(ReplyError, match=r"ends in a checksum .*comm\.checksum to 0"):
        stage.connect()
    assert not any(c.split()[2:3] in (["move"], ["home"]) for c in emu.commands)


def test_stage_move_timeout_stops_axis(clock: SimClock) -> None:
    stage, emu = make_stage(clock, timeout_margin_s=0.0)
    stage.home()
    emu.maxspeed = 1  # far slower than the driver believes
    # it answered every poll: a blocked or slow axis, not a dead link (a second reader: it was
    # an InstrumentTimeout, which the run called "stage stopped answering")
    with pytest.raises(MoveTimeout, match=r"not finished.*controller answered.*; stopped$"):
        stage.move_to(0.1)
    assert not emu.busy()  # "stopped" is said once the axis is at rest


def test_an_interrupted_homing_is_not_taken_for_a_homed_stage(clock: SimClock) -> None:
    """A second reader: a homing cut short (WR, no reference, still set) returned as if it had
    homed; the run then failed at its first point with "stage not homed"."""
    stage, emu = make_stage(clock)
    real = emu.handle

    def cut_short(message: bytes) -> str | None:
        if b"get pos" in message and emu.busy():
            emu._halt()  # stopped where it is: no reference found, WR stays
        return real(message)

    emu.handle = cut_short  # type: ignore[method-assign]
    with pytest.raises(NotHomedError, match="homing ended without a reference"):
        stage.home()
    emu.handle = real  # type: ignore[method-assign]
    assert not stage.is_homed()


def test_a_reply_from_another_axis_is_refused(clock: SimClock) -> None:
    """A second reader: the reply's axis number was never checked."""
    stage, emu = make_stage(clock)
    stage.home()
    real = emu.handle

    def other_axis(message: bytes) -> str | None:
        reply = real(message)
        return reply.replace("@01 1 ", "@01 2 ", 1) if reply is not None else None

    emu.handle = other_axis  # type: ignore[method-assign]
    with pytest.raises(ReplyError, match="from axis 2"):
        stage.position()


def test_clearing_a_stall_leaves_the_stage_to_be_homed(clock: SimClock) -> None:
    """A second reader: clear_warnings() dropped a stall (FS) and the stage counted as homed,
    though its position may have slipped; connect() already asked for a new homing."""
    stage, emu = make_stage(clock)
    stage.home()
    assert stage.is_homed()
    emu.stall()
    with pytest.raises(StallError):
        stage.move_to(0.1)
    assert "FS" in stage.clear_warnings()
    assert not stage.is_homed()
    stage.home()
    assert stage.is_homed()


EIGHT_POINTS = bytes(16)  # 8 DAC codes of 0, the emulator's minimum


@pytest.mark.parametrize(
    ("block", "accepted"),
    [
        (b"#216" + EIGHT_POINTS, True),  # n = 2 digits, 16 bytes
        (b"#3016" + EIGHT_POINTS, True),  # leading zero in a 3-digit count
        (b"#217" + EIGHT_POINTS, False),  # announces 17, holds 16
        (b"#016" + EIGHT_POINTS, False),  # n = 0 (the indefinite form) is no definite block
        (b"#2x6" + EIGHT_POINTS, False),  # count not a digit
    ],
)
def test_emulator_parses_arbitrary_blocks_by_the_standard(
    clock: SimClock, block: bytes, accepted: bool
) -> None:
    """IEEE 488.2 definite-length blocks as raw bytes, independent of the driver's encoder."""
    gen, emu = make_generator(clock)
    emu.handle(b"SOUR1:DATA:ARB:DAC X," + block)
    assert ("-161,Invalid block data" in gen.errors()) is not accepted
