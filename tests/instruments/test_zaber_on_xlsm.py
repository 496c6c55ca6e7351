"""The stage driver against an independent model of an X-LSM500A (``xlsm_model``): microstep
from the bench file's model, identity checked at connect, replies matched by message id."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

import protocols
from daq.connect import stage_settings
from instruments.errors import InstrumentTimeout, LimitError
from instruments.zaber import ZaberStage
from protocols.bench import BenchSpec, load_bench
from tests.instruments.xlsm_model import MICROSTEP_UM, XLSM500A, LineLink

LAB_BENCH = Path(protocols.__file__).parent / "benches" / "lab_bench.yaml"


class NoWait:
    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, dt_s: float) -> None:
        self.t += max(dt_s, 0.0)


def lab() -> BenchSpec:
    return load_bench(LAB_BENCH).bench


def lab_stage(device: XLSM500A, **overrides: object) -> ZaberStage:
    settings = replace(stage_settings(lab(), NoWait()), **overrides)  # type: ignore[arg-type]
    return ZaberStage(LineLink(device), settings)


def test_all_31_lab_cylinders_reached_within_10_um_on_the_device() -> None:
    bench = lab()
    positions = [float(p) for p in bench.positions_m()]
    assert len(positions) == 31
    model = XLSM500A()
    stage = lab_stage(model)
    ident = stage.connect(positions)
    assert ident["microstep_m"] == pytest.approx(MICROSTEP_UM * 1e-6, rel=1e-12)
    assert ident["device_id"] == model.device_id and ident["resolution"] == 64
    stage.home()
    for p in positions:
        stage.move_to(p)
        # the device's own position, in its own microsteps (not the driver's read-back)
        assert abs(model.position_um() - p * 1e6) < 10.0, p


@pytest.mark.parametrize(
    ("overrides", "device", "message"),
    [
        ({"microstep_m": 0.49609375e-6}, {}, "disagrees with X-LSM500A"),
        ({"model": None, "microstep_m": 0.047625e-6}, {"resolution": 128}, "resolution 128"),
        ({"model": "X-LSM50A"}, {}, "X-LSM50A has 50 mm"),
        ({"device_id": 4242}, {}, "device id 50123, the bench file expects 4242"),
        ({"model": "A-LSQ150D"}, {}, "microstep unknown"),
    ],
)
def test_connect_refuses_a_stage_that_is_not_the_bench_files(
    overrides: dict[str, object], device: dict[str, int], message: str
) -> None:
    model = XLSM500A()
    for k, v in device.items():
        setattr(model, k, v)
    stage = lab_stage(model, **overrides)
    with pytest.raises(LimitError, match=message):
        stage.connect()
    with pytest.raises(LimitError):  # and nothing moves
        stage.move_to(0.1)
    assert model.moves == [] and not model.homed


def test_connect_refuses_positions_outside_the_travel() -> None:
    model = XLSM500A()
    model.limit_max = int(300_000 / MICROSTEP_UM)  # a shorter stage on the port
    stage = lab_stage(model, model=None, microstep_m=MICROSTEP_UM * 1e-6)
    positions = [float(p) for p in lab().positions_m()]
    with pytest.raises(LimitError, match=r"cylinder 22 at 305.6000 mm is outside the device's"):
        stage.connect(positions)


def test_late_reply_is_never_taken_for_the_next_answer() -> None:
    model = XLSM500A()
    stage = lab_stage(model)
    stage.connect()
    model.late = 1  # the reply to the next command misses its timeout
    with pytest.raises(InstrumentTimeout):
        stage.speed()  # 'get maxspeed' -> no reply in time
    # the late maxspeed reply now sits before the position's reply on the line
    assert stage.position() == pytest.approx(model.pos * MICROSTEP_UM * 1e-6)
    assert stage.position() == pytest.approx(model.pos * MICROSTEP_UM * 1e-6)


def test_emulator_late_reply_is_never_taken_for_the_next_answer() -> None:
    from sim_backend.emulators import SimClock, SimTransport, ZaberEmulator

    clock = SimClock()
    emu = ZaberEmulator(clock, model="X-LSM500A", travel_m=(0.0, 0.5))
    stage = ZaberStage(SimTransport(emu, "stage", 1.0, clock), lab_stage(XLSM500A()).settings)
    stage.connect()
    emu.late_replies = 1
    with pytest.raises(InstrumentTimeout):
        stage.speed()
    assert stage.position() == pytest.approx(emu.position_m(), abs=1e-9)
