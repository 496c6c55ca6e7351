"""Zaber stage driver on the scripted fake: replies, flags, limits, same-side approach."""

from __future__ import annotations

import pytest

from instruments.errors import LimitError, NotHomedError, ReplyError, StallError
from instruments.transport import ScriptedTransport
from instruments.zaber import ZaberSettings, ZaberStage, parse_reply

STEP = 1e-6


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0
        self.sleeps: list[float] = []

    def now(self) -> float:
        return self.t

    def sleep(self, dt_s: float) -> None:
        self.sleeps.append(dt_s)
        self.t += dt_s


def settings(**kw: object) -> ZaberSettings:
    base = dict(
        microstep_m=STEP,
        soft_limits_m=(0.01, 0.2),
        clock=FakeClock(),
        approach_m=0.0,
        settle_s=0.1,
        message_ids=False,
    )
    base.update(kw)
    return ZaberSettings(**base)  # type: ignore[arg-type]


LIMITS = [  # what connect() reads before the first move
    ("/1 1 warnings", "@01 1 OK IDLE -- 00"),
    ("/1 1 get device.id", "@01 1 OK IDLE -- 50500"),
    ("/1 1 get version", "@01 1 OK IDLE -- 7.29"),
    ("/1 1 get resolution", "@01 1 OK IDLE -- 64"),
    ("/1 1 get limit.min", "@01 1 OK IDLE -- 0"),
    ("/1 1 get limit.max", "@01 1 OK IDLE -- 300000"),
]


def test_parse_reply() -> None:
    r = parse_reply("@01 1 OK IDLE -- 0")
    assert (r.device, r.axis, r.ok, r.busy, r.flag, r.data) == (1, 1, True, False, "--", "0")
    assert parse_reply("@01 1 RJ BUSY WR BADDATA").flag == "WR"
    with pytest.raises(ReplyError):
        parse_reply("garbage")


def test_limits_intersect_soft_limits() -> None:
    stage = ZaberStage(ScriptedTransport(LIMITS), settings(soft_limits_m=(0.01, 0.5)))
    assert stage.limits() == pytest.approx((0.01, 0.3))


def test_move_out_of_limits_refused_before_moving() -> None:
    t = ScriptedTransport(LIMITS)
    stage = ZaberStage(t, settings())
    with pytest.raises(
        LimitError, match=r"target 250.0000 mm outside the travel \[10.0000, 200.0000\] mm"
    ):
        stage.move_to(0.25)
    assert not any("move" in c for c in t.sent)
    with pytest.raises(LimitError, match="not finite"):
        stage.move_to(float("nan"))


def test_move_refused_when_not_homed() -> None:
    t = ScriptedTransport([*LIMITS, ("/1 1 warnings", "@01 1 OK IDLE WR 01 WR")])
    with pytest.raises(NotHomedError, match="not homed"):
        ZaberStage(t, settings()).move_to(0.05)
    assert t.done


def test_move_polls_until_idle_then_settles() -> None:
    clock = FakeClock()
    t = ScriptedTransport(
        [
            *LIMITS,
            ("/1 1 warnings", "@01 1 OK IDLE -- 00"),
            ("/1 1 set maxspeed 40960", "@01 1 OK IDLE -- 0"),
            ("/1 1 get pos", "@01 1 OK IDLE -- 20000"),
            ("/1 1 move abs 50000", "@01 1 OK BUSY -- 0"),
            ("/1 1 get pos", "@01 1 OK BUSY -- 0"),
            ("/1 1 get pos", "@01 1 OK IDLE -- 0"),
            ("/1 1 get pos", "@01 1 OK IDLE -- 50000"),
        ]
    )
    stage = ZaberStage(t, settings(clock=clock))
    stage.move_to(0.05)
    assert t.done
    assert clock.sleeps == [0.05, 0.1]  # one poll, then the settle delay


def test_same_side_approach_from_below() -> None:
    t = ScriptedTransport(
        [
            *LIMITS,
            ("/1 1 warnings", "@01 1 OK IDLE -- 00"),
            ("/1 1 set maxspeed 40960", "@01 1 OK IDLE -- 0"),
            ("/1 1 get pos", "@01 1 OK IDLE -- 100000"),
            ("/1 1 move abs 49000", "@01 1 OK BUSY -- 0"),
            ("/1 1 get pos", "@01 1 OK IDLE -- 0"),
            ("/1 1 move abs 50000", "@01 1 OK BUSY -- 0"),
            ("/1 1 get pos", "@01 1 OK IDLE -- 0"),
            ("/1 1 get pos", "@01 1 OK IDLE -- 50000"),
        ]
    )
    ZaberStage(t, settings(approach_m=1e-3)).move_to(0.05)
    assert t.done


def test_stall_flag_and_rejection_are_errors() -> None:
    t = ScriptedTransport(
        [
            *LIMITS,
            ("/1 1 set maxspeed 40960", "@01 1 OK IDLE -- 0"),  # before anything moves
            ("/1 1 get limit.approach.maxspeed", "@01 1 OK IDLE -- 40960"),
            ("/1 1 home", "@01 1 OK IDLE FS 0"),
            ("/1 1 get foo", "@01 1 RJ IDLE -- BADCOMMAND"),
        ]
    )
    stage = ZaberStage(t, settings())
    with pytest.raises(StallError, match="stalled and stopped"):
        stage.home()
    with pytest.raises(ReplyError, match="rejected \\(BADCOMMAND\\)"):
        stage.command("get foo")


def test_settings_validate() -> None:
    with pytest.raises(LimitError, match="speed_m_per_s must be > 0"):
        ZaberSettings(speed_m_per_s=0.0)
    with pytest.raises(LimitError, match="low < high"):
        ZaberSettings(soft_limits_m=(0.2, 0.1))


def test_alert_and_info_lines_are_skipped() -> None:
    t = ScriptedTransport([*LIMITS, ("/1 1 get pos", "!01 1 IDLE --")], name="stage")
    stage = ZaberStage(t, settings())
    stage.connect()
    t._pending.append("@01 1 OK IDLE -- 1234")  # the reply following the alert
    assert stage.position() == pytest.approx(1234 * STEP)
