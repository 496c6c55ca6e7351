"""The ETA on a loaded machine, with a fake clock: it is refined from the measured time of the
points, counted from the end of one point to the end of the next (what the progress display
costs between points included), and the simulated bench's prior follows the machine's load."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

import daq.engine.engine as engine_mod
import daq.engine.eta as eta_mod
from daq.cli import run_protocol as rp
from daq.engine import EventKind, RunEngine, RunEvent

from .fakes import FakeWorld, fake_bench


class FakeClock:
    """``time.monotonic`` that moves only when the test says so."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_eta_counts_the_time_between_points(protocol, bench, out, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """The instruments take no time on the fake clock; the progress display takes 1 s per point
    (a terminal on a busy machine). The time left after each point is 1 s per point left: the
    ETA said 0 when it counted only the time inside the points."""
    clock = FakeClock()
    monkeypatch.setattr(engine_mod, "time", SimpleNamespace(monotonic=clock))
    eng = RunEngine(protocol, bench, fake_bench(FakeWorld()), out)
    seen: list[tuple[float, int]] = []

    def slow_display(event: RunEvent) -> None:
        if event.kind == EventKind.PROGRESS:
            seen.append((float(event.data["eta_s"]), event.data["total"] - event.data["done"]))
            clock.t += 1.0

    eng.subscribe(slow_display)
    assert eng.run().status == "complete"
    assert len(seen) == 12
    # from the second burst on, every kind of point has been measured beyond the first point
    for eta_s, left in seen[3:]:
        assert eta_s == pytest.approx(1.0 * left)


def test_estimator_follows_a_machine_slower_than_its_priors() -> None:
    """Fake point times three times the priors (a loaded machine): after the first point of
    each kind the time left is three times the prior's."""
    costs = eta_mod.PointCosts(point_s=0.01, arm_s=1.0, basis="test")
    arms = [True, False, False, False, True, False, False, False]
    est = eta_mod.EtaEstimator(costs, arms)
    for k in range(4):
        est.measured(3.0 * (costs.point_s + (costs.arm_s if arms[k] else 0.0)))
    assert est.remaining_s() == pytest.approx(3.0 * (costs.arm_s + 4 * costs.point_s))


def test_simulated_bench_prior_follows_the_machine_load(capsys, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    monkeypatch.setattr(eta_mod, "_model_compiled", lambda: True)
    import os

    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    monkeypatch.setattr(os, "getloadavg", lambda: (0.0, 0.0, 0.0))
    assert rp.main(["smoke", "--dry-run"]) == 0
    idle = capsys.readouterr().out
    monkeypatch.setattr(os, "getloadavg", lambda: (5.0, 5.0, 5.0))
    assert rp.main(["smoke", "--dry-run"]) == 0
    busy = capsys.readouterr().out
    assert "machine's load" not in idle and "(x3.0 for the machine's load)" in busy

    def seconds(text: str) -> float:
        return float(text.split("(")[1].split(" s,")[0])

    assert seconds(busy) == pytest.approx(3.0 * seconds(idle), rel=1e-6)
