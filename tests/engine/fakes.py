"""Tiny in-test fake instruments behind the Protocols of ``instruments.interfaces``.

The fake world makes a deterministic 'velocity' per (direction, Vpp, stage position) plus
noise seeded by (seed, point, repeat count), so a resumed run reproduces an uninterrupted one.
"""

from __future__ import annotations

import hashlib
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from daq.engine import BenchInstruments
from instruments.errors import InstrumentTimeout, StallError
from instruments.interfaces import Acquisition, AcquisitionConfig, BurstConfig
from protocols.runfile import ChainInfo

SENS = 0.05  # (m/s)/V
DELAY_S = 20e-6


@dataclass
class Faults:
    timeouts: int = 0  # the next N reads time out
    stall_on_move: int | None = None  # the Nth move (0-based) stalls
    nan_reads: int = 0
    read_sleep_s: float = 0.0  # wall time per read (to abort / kill mid-scan)
    clip: bool = False
    generator_dead_after_reads: int | None = None  # the generator stops answering after N reads
    home_s: float = 0.0  # wall time homing takes (a cancel ends it, not homed)
    stage_keeps_moving: bool = False  # the axis still moves after stop (a controller fault)
    signal_lost_after_reads: int | None = None  # the beam loses the surface after N reads

    def signal_lost(self, reads: int) -> bool:
        return self.signal_lost_after_reads is not None and reads >= self.signal_lost_after_reads


@dataclass
class FakeWorld:
    seed: int = 0
    faults: Faults = field(default_factory=Faults)
    outputs: dict[int, bool] = field(default_factory=lambda: {1: False, 2: False})
    bursts: dict[int, BurstConfig] = field(default_factory=dict)
    position_m: float = 0.0
    homed: bool = False
    moves: int = 0
    triggers: int = 0
    reads: int = 0
    safe_calls: int = 0
    armed: bool = False
    latched: tuple[int, float] | None = None
    counts: dict[Any, int] = field(default_factory=dict)
    config: AcquisitionConfig | None = None
    range_name: str = "VD-09 50mm/s/V"


class FakeGenerator:
    """Timeouts once dead (commands are lost, outputs stay as they were), like a cut link."""

    def __init__(self, w: FakeWorld) -> None:
        self.w = w
        self.queries = 0  # queries that went unanswered

    def _dead(self) -> bool:
        n = self.w.faults.generator_dead_after_reads
        return n is not None and self.w.reads >= n

    def _silent(self, what: str) -> None:
        if self._dead():
            self.queries += 1
            raise InstrumentTimeout(f"fake generator: no reply to {what!r} within 5 s")

    def identify(self) -> str:
        return "FAKE,GEN"

    def configure_burst(self, channel: int, config: BurstConfig) -> None:
        self.w.bursts[channel] = config

    def output(self, channel: int, on: bool) -> None:
        if self._dead():
            return  # a write into a dead link: lost, no error
        self.w.outputs[channel] = on

    def output_state(self, channel: int) -> bool:
        self._silent(f"OUTP{channel}?")
        return self.w.outputs[channel]

    def trigger(self) -> None:
        if self._dead():
            return
        self.w.triggers += 1
        on = [ch for ch, o in self.w.outputs.items() if o]
        if self.w.armed and on:
            self.w.latched = (on[0], self.w.bursts[on[0]].amplitude_Vpp)

    def wait_complete(self, timeout_s: float | None = None) -> None:
        self._silent("*OPC?")

    def errors(self) -> list[str]:
        self._silent("SYST:ERR?")
        return []

    def snapshot(self) -> dict[str, Any]:
        return {"outputs": dict(self.w.outputs)}

    def safe_state(self) -> None:
        self.w.safe_calls += 1
        if self._dead():
            return
        for ch in self.w.outputs:
            self.w.outputs[ch] = False

    def close(self) -> None:
        pass


class FakeVibrometer:
    def __init__(self, w: FakeWorld) -> None:
        self.w = w

    def identify(self) -> str:
        return "FAKE,VIB"

    def velocity_range(self) -> str:
        return self.w.range_name

    def set_velocity_range(self, name: str) -> None:
        self.w.range_name = name

    def sensitivity_m_per_s_per_V(self) -> float:
        return SENS

    def bandwidth_Hz(self) -> float:
        return 100e3

    def signal_delay_s(self) -> float:
        return DELAY_S

    def signal_level(self) -> float:
        return 0.0 if self.w.faults.signal_lost(self.w.reads) else 0.9

    def snapshot(self) -> dict[str, Any]:
        return {"range": self.w.range_name}

    def safe_state(self) -> None:
        pass

    def close(self) -> None:
        pass


class FakeStage:
    def __init__(self, w: FakeWorld) -> None:
        self.w = w

    def home(self, cancel: threading.Event | None = None) -> None:
        if self.w.faults.home_s > 0 and (cancel or threading.Event()).wait(self.w.faults.home_s):
            return  # cancelled: stopped short of home
        self.w.homed = True
        self.w.position_m = 0.0

    def is_homed(self) -> bool:
        return self.w.homed

    def move_to(self, position_m: float) -> None:
        n = self.w.moves
        self.w.moves += 1
        if self.w.faults.stall_on_move is not None and n >= self.w.faults.stall_on_move:
            raise StallError(f"stage stalled at {self.w.position_m * 1e3:.1f} mm (flag FS)")
        self.w.position_m = position_m

    def position(self) -> float:
        return self.w.position_m

    def stop(self) -> None:
        pass

    def is_moving(self) -> bool:
        return self.w.faults.stage_keeps_moving

    def limits(self) -> tuple[float, float]:
        return (0.0, 0.5)

    def snapshot(self) -> dict[str, Any]:
        return {"position_m": self.w.position_m}

    def safe_state(self) -> None:
        pass

    def close(self) -> None:
        pass


def expected_velocity_m_per_s(
    channel: int, vpp: float, position_m: float, t: np.ndarray
) -> np.ndarray:
    """The noiseless true velocity the fake world produces."""
    f = 8000.0 if channel == 1 else 6000.0
    return 1e-3 * vpp * (1 + position_m) * np.sin(2 * np.pi * f * t) * (t > 0)


class FakeDigitiser:
    def __init__(self, w: FakeWorld) -> None:
        self.w = w

    def configure(self, config: AcquisitionConfig) -> float:
        self.w.config = config
        return config.sample_rate_Hz

    def arm(self) -> None:
        self.w.armed = True
        self.w.latched = None

    def read(self) -> Acquisition:
        w, cfg = self.w, self.w.config
        assert cfg is not None
        w.armed = False
        if w.faults.read_sleep_s:
            time.sleep(w.faults.read_sleep_s)
        dead = w.faults.generator_dead_after_reads
        if dead is not None and w.reads >= dead:  # no trigger from a dead generator
            raise InstrumentTimeout("fake digitiser: no trigger within the timeout")
        if w.faults.timeouts > 0:
            w.faults.timeouts -= 1
            raise InstrumentTimeout("fake digitiser: no trigger within the timeout")
        lost = w.faults.signal_lost(w.reads)  # reads before this one
        w.reads += 1
        t = (np.arange(cfg.n_samples) - cfg.n_pretrigger) / cfg.sample_rate_Hz
        if w.latched is None or lost:
            v_true = np.zeros_like(t)
            ref = np.zeros_like(t)
            key: Any = ("quiet",)
        else:
            ch, vpp = w.latched
            v_true = expected_velocity_m_per_s(ch, vpp, w.position_m, t - DELAY_S)
            ref = 0.5 * vpp * np.sin(2 * np.pi * 8000.0 * t) * (t > 0)
            key = (ch, round(vpp, 12), round(w.position_m, 9))
        n = w.counts.get(key, 0)
        w.counts[key] = n + 1
        digest = hashlib.sha1(repr((key, n)).encode()).digest()
        rng = np.random.default_rng([w.seed, int.from_bytes(digest[:4], "little")])
        volts = v_true / SENS + rng.normal(0, 1e-4, t.shape)
        if w.faults.clip:
            volts[:] = 10.0
        if w.faults.nan_reads > 0:
            w.faults.nan_reads -= 1
            volts[:] = np.nan
        return Acquisition(cfg.sample_rate_Hz, volts, ref, cfg.n_pretrigger)

    def snapshot(self) -> dict[str, Any]:
        return {"reads": self.w.reads}

    def safe_state(self) -> None:
        self.w.armed = False

    def close(self) -> None:
        pass


def fake_chain(n: int = 31) -> ChainInfo:
    lengths = np.linspace(0.09, 0.11, n)
    return ChainInfo(lengths, 0.0136, 5.0, 1e9, np.ones((n, 2)), 2 * np.ones((n, 2)))


def fake_bench(world: FakeWorld | None = None) -> BenchInstruments:
    w = world or FakeWorld()
    return BenchInstruments(
        generator=FakeGenerator(w),
        vibrometer=FakeVibrometer(w),
        stage=FakeStage(w),
        digitiser=FakeDigitiser(w),
        chain=fake_chain(),
        backend="sim",
        sleep=lambda dt: None,
        world=w,
    )
