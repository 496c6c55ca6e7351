"""The bench file's stage speed against the device's range of ``maxspeed`` (the ASCII protocol
manual: data 1 to resolution x 16384, 30.48 mm/s on an X-LSM at resolution 64). Before, the
speed was sent only before the first move, after homing: a speed the device refuses failed the
run minutes in, as a bare "'set maxspeed ...' rejected". Now connect sets it, so ``biafc check``
and a run's connect refuse it in one line naming ``stage.speed``, before anything moves."""

from __future__ import annotations

import pytest

from instruments.errors import LimitError
from instruments.zaber import ZaberSettings, ZaberStage
from sim_backend.emulators import SimClock, SimTransport, ZaberEmulator


def _stage(speed_m_per_s: float) -> tuple[ZaberStage, ZaberEmulator]:
    clock = SimClock()
    emu = ZaberEmulator(clock, model="X-LSM500A", travel_m=(0.0, 0.5))
    settings = ZaberSettings(model="X-LSM500A", speed_m_per_s=speed_m_per_s, clock=clock)
    return ZaberStage(SimTransport(emu, "stage", 1.0, clock), settings), emu


def test_a_speed_past_the_devices_range_is_refused_at_connect_naming_the_field() -> None:
    stage, emu = _stage(0.040)
    with pytest.raises(LimitError, match=r"stage\.speed 40 mm/s .*range ends at 30\.48 mm/s"):
        stage.connect()
    assert not any(c.split()[-1] in ("home",) or " move " in c for c in emu.commands)
    assert emu.maxspeed != round(0.040 / emu.microstep_m * 1.6384)  # kept the old setting


def test_a_speed_within_the_range_is_set_at_connect() -> None:
    stage, emu = _stage(0.030)
    stage.connect()
    assert emu.maxspeed == round(0.030 / emu.microstep_m * 1.6384)
    assert any("set maxspeed" in c for c in emu.commands)
    stage.home()  # and it is not sent again
    assert sum("set maxspeed" in c for c in emu.commands) == 1
    assert stage.speed() == pytest.approx(0.030, rel=1e-6)


def test_the_ceiling_is_the_same_speed_at_another_resolution() -> None:
    for speed, ok in ((0.030, True), (0.031, False)):
        clock = SimClock()
        emu = ZaberEmulator(clock, model="X-LSM500A", travel_m=(0.0, 0.5), resolution=32)
        settings = ZaberSettings(model="X-LSM500A", resolution=32, speed_m_per_s=speed, clock=clock)
        stage = ZaberStage(SimTransport(emu, "stage", 1.0, clock), settings)
        if ok:
            stage.connect()
            assert stage.speed() == pytest.approx(speed, rel=1e-5)
        else:
            with pytest.raises(LimitError, match=r"range ends at 30\.48 mm/s"):
                stage.connect()
