"""The bench file's stage speed against the range of ``maxspeed`` (the firmware 6 ASCII protocol
manual: data 1 to resolution x 16384, 30.48 mm/s on an X-LSM at any resolution). Before, the
speed was sent only before the first move, after homing: a speed the device refuses failed the
run minutes in, as a bare "'set maxspeed ...' rejected". Now connect refuses it in one line
naming ``stage.speed``, without sending anything (``biafc check`` only reads), and a device that
refuses the speed when it is set (a firmware with another range) is the same kind of line."""

from __future__ import annotations

import pytest

from instruments.errors import LimitError
from instruments.zaber import ZaberSettings, ZaberStage
from sim_backend.emulators import SimClock, SimTransport, ZaberEmulator


def _stage(speed_m_per_s: float, resolution: int = 64) -> tuple[ZaberStage, ZaberEmulator]:
    clock = SimClock()
    emu = ZaberEmulator(clock, model="X-LSM500A", travel_m=(0.0, 0.5), resolution=resolution)
    settings = ZaberSettings(
        model="X-LSM500A", resolution=resolution, speed_m_per_s=speed_m_per_s, clock=clock
    )
    return ZaberStage(SimTransport(emu, "stage", 1.0, clock), settings), emu


def test_a_speed_past_the_range_is_refused_at_connect_naming_the_field() -> None:
    stage, emu = _stage(0.040)
    with pytest.raises(LimitError, match=r"stage\.speed 40 mm/s .*range ends at 30\.48 mm/s"):
        stage.connect()
    assert not any(c.split()[2:3] == ["set"] or " set " in c for c in emu.commands)
    assert not any(" home" in c or " move " in c for c in emu.commands)


def test_connect_sends_no_setting_and_the_speed_goes_out_before_the_stage_moves() -> None:
    stage, emu = _stage(0.030)
    before = emu.maxspeed
    stage.connect()
    assert not any("set " in c for c in emu.commands)  # biafc check only reads
    assert emu.maxspeed == before
    stage.home()
    assert sum("set maxspeed" in c for c in emu.commands) == 1
    assert stage.speed() == pytest.approx(0.030, rel=1e-6)


def test_the_ceiling_is_the_same_speed_at_another_resolution() -> None:
    stage, _ = _stage(0.030, resolution=32)
    stage.connect()
    stage.home()
    assert stage.speed() == pytest.approx(0.030, rel=1e-5)
    stage, _ = _stage(0.031, resolution=32)
    with pytest.raises(LimitError, match=r"range ends at 30\.48 mm/s"):
        stage.connect()


def test_a_device_that_refuses_the_speed_when_it_is_set_names_the_field() -> None:
    stage, emu = _stage(0.030)
    stage.connect()
    emu.resolution = 32  # a device whose range ends lower than the manual's (firmware 7?)
    emu.microstep_m *= 2
    with pytest.raises(LimitError, match=r"stage\.speed 30 mm/s .*refused 'set maxspeed \d+' "
                                         r"\(BADDATA\)"):  # fmt: skip
        stage.home()
    assert not any(" home" in c for c in emu.commands)  # refused before the stage moved


def test_the_longest_homing_is_at_the_bench_files_speed() -> None:
    """The run says how long homing may take before it starts; it read the device's stored
    speed, which homing replaces with the bench file's first: 20 mm/s stored and 2 mm/s in the
    bench file said "at most 25 s" for a homing of up to 250 s."""
    clock = SimClock()
    emu = ZaberEmulator(clock, model="X-LSM500A", travel_m=(0.0, 0.5), speed_m_per_s=0.020)
    emu.approach_maxspeed = emu.maxspeed
    settings = ZaberSettings(model="X-LSM500A", speed_m_per_s=0.002, clock=clock)
    stage = ZaberStage(SimTransport(emu, "stage", 1.0, clock), settings)
    stage.connect()
    longest = stage.home_time_s()
    assert longest == pytest.approx(0.5 / 0.002, rel=1e-3)
    t0 = clock.now()
    stage.home()
    assert clock.now() - t0 <= longest
