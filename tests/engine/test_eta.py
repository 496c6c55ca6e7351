"""The ETA: estimated from the bench that will run it (the simulated bench: from the model's
cost, not from the settle and record times it never waits), refined from measured point times."""

from __future__ import annotations

import re
import statistics
from pathlib import Path

import pytest

import daq.engine.eta as eta_mod
from daq.cli import run_protocol as rp
from daq.engine import EventKind, RunEngine, RunEvent, make_plan
from daq.engine.eta import EtaEstimator, PointCosts, arms_burst
from protocols.bench import load_bench
from protocols.schema import load_protocol
from tests.kernel_index import write_fresh_index

from .fakes import FakeWorld, Faults, fake_bench

LAB_BENCH = Path(rp.__file__).resolve().parents[2] / "protocols" / "benches" / "lab_bench.yaml"


def _dry_run_s(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[float, str]:
    assert rp.main([*argv, "--dry-run"]) == 0
    out = capsys.readouterr().out
    m = re.search(r"estimated [0-9:]+ \(([0-9.]+) s, from ([^)]*\)?)[^;]*\);", out)
    assert m, out
    return float(m.group(1)), out


def test_sim_bench_dry_run_estimates_from_the_model(capsys, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """ltr_highamp on the simulated bench: 0.4 s of work, the dry run said 00:26 (the settle
    and record times a real bench would wait)."""
    monkeypatch.setattr(eta_mod, "_model_compiled", lambda: True)
    sim_s, out = _dry_run_s(capsys, "ltr_highamp")
    assert "from the model's cost on the simulated bench" in out
    assert 0.05 < sim_s < 3.0
    lab_s, out = _dry_run_s(capsys, "ltr_highamp", "--bench", str(LAB_BENCH))
    assert "from the bench's settle, record and stage times" in out
    # 31 points x (50 ms settle + 4 x (1 + 25 + 50) ms records), plus stage moves
    assert 31 * (0.05 + 4 * 0.076) <= lab_s < 40.0


def test_sim_bench_estimate_includes_the_first_compile(capsys, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    monkeypatch.setattr(eta_mod, "_model_compiled", lambda: False)
    s, out = _dry_run_s(capsys, "smoke")
    assert s >= eta_mod.COMPILE_S and "compiled first" in out and "once" in out


def test_dry_run_says_how_long_homing_may_take(capsys, monkeypatch, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A run homes a stage that is not homed before its first point: minutes on the rig,
    said by the run only once it had started (the dry run's line left it out)."""
    monkeypatch.setattr(eta_mod, "_model_compiled", lambda: True)
    _, out = _dry_run_s(capsys, "smoke", "--bench", str(LAB_BENCH))
    # the template's X-LSM500A: 500 mm at 25 mm/s
    assert "the stage homes if it is not homed: at most 20 s (X-LSM500A: 500 mm at 25 mm/s" in out
    slow = tmp_path / "slow_stage.yaml"
    text = LAB_BENCH.read_text().replace("speed: 25 mm/s", "speed: 2 mm/s")
    text = text.replace("  model: X-LSM500A", "  microstep: 0.047625 um\n  # model:")
    slow.write_text(text)
    _, out = _dry_run_s(capsys, "smoke", "--bench", str(slow))  # no model: the soft limit
    assert "at most 4 min 0 s (the upper soft limit: 480 mm at 2 mm/s" in out
    _, out = _dry_run_s(capsys, "smoke")  # the simulated bench waits for nothing
    assert "homes" not in out
    paced = tmp_path / "paced.yaml"  # ... unless it runs paced: 10x real time
    paced.write_text(load_bench().text.replace("speedup: 0", "speedup: 10"))
    _, out = _dry_run_s(capsys, "smoke", "--bench", str(paced))
    assert "at most 2 s (500 mm at 25 mm/s, x1/10)" in out


def test_sim_bench_cost_counts_a_model_run_per_burst(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    monkeypatch.setattr(eta_mod, "_model_compiled", lambda: True)
    bench = load_bench()
    one = make_plan(load_protocol("ltr_highamp"), bench)  # 1 burst, 31 points
    sweep = make_plan(load_protocol("biafc_sweep"), bench)  # 16 amplitudes x 31 cylinders
    assert one.costs is not None and sweep.costs is not None
    assert one.costs.arm_s > 10 * one.costs.point_s  # a model run against an emulated record
    assert sum(arms_burst(sweep.points)) == 16
    assert sweep.estimated_s > 15 * one.costs.arm_s


def test_estimator_refines_each_kind_from_measured_times() -> None:
    costs = PointCosts(point_s=1.0, arm_s=10.0, basis="test")
    arms = [True, False, False, False, True, False, False, False]
    est = EtaEstimator(costs, arms)
    assert est.total_s() == pytest.approx(8 * 1.0 + 2 * 10.0)
    est.measured(30.0)  # the first point: compile + model run
    assert est.remaining_s() == pytest.approx(6 * 1.0 + 30.0)  # an arming point as measured
    est.measured(0.1)
    est.measured(0.3)
    assert est.remaining_s() == pytest.approx(4 * 0.2 + 30.0)  # median of the measured
    est.measured(0.2)
    est.measured(2.0)  # the second arming point replaces the first (its one-time cost)
    assert est.remaining_s() == pytest.approx(3 * 0.2)
    for _ in range(3):
        est.measured(0.2)
    assert est.remaining_s() == 0.0


class _Watched(list):  # type: ignore[type-arg]
    """A list that counts the elements read through iteration (what a sort or a sum reads)."""

    reads = 0

    def __iter__(self):  # type: ignore[no-untyped-def]
        for x in super().__iter__():
            _Watched.reads += 1
            yield x


def test_an_estimate_reads_a_handful_of_times_however_long_the_run() -> None:
    """Each ETA update took the median of every measured time once per point left: on a run of
    20,000 points, about 10^8 reads per point at its middle (8.2 s of a 1,240-point simulated
    run's 19.6 s); now a few, whatever the run's length. The result is the same."""
    costs = PointCosts(point_s=1.0, arm_s=10.0, basis="test")
    arms = arms_burst([type("P", (), {"direction": "ltr", "amplitude_index": i // 31})()
                       for i in range(2000)])  # fmt: skip
    est = EtaEstimator(costs, arms)
    times = [0.5 + (i * 7919 % 101) / 100 for i in range(1000)]
    for t in times:
        est.measured(t)
    est._times = {k: _Watched(v) for k, v in est._times.items()}
    _Watched.reads = 0
    left = est.remaining_s()
    assert _Watched.reads <= 10
    arming = sum(arms[1000:])
    med = {k: statistics.median(list.__iter__(v)) for k, v in est._times.items()}
    assert left == pytest.approx(arming * med[True] + (1000 - arming) * med[False], rel=1e-12)


def test_engine_eta_follows_the_measured_point_times(protocol, bench, out) -> None:  # type: ignore[no-untyped-def]
    """The fake bench takes 2 x 40 ms per point (two averages): far more than the simulated
    bench's prior; after a few points the ETA is the measured time of the points left."""
    world = FakeWorld(faults=Faults(read_sleep_s=0.04))
    eng = RunEngine(protocol, bench, fake_bench(world), out)
    events: list[RunEvent] = []
    eng.subscribe(events.append)
    assert eng.run().status == "complete"
    progress = [e.data for e in events if e.kind == EventKind.PROGRESS]
    assert len(progress) == 12
    d = progress[5]  # 6 done, 6 left
    per_point = d["elapsed_s"] / 6
    assert 0.5 * 6 * per_point < d["eta_s"] < 2.0 * 6 * per_point
    assert progress[-1]["eta_s"] == 0.0
    started = next(e.data for e in events if e.kind == EventKind.RUN_STARTED)
    assert started["estimate_basis"] and started["estimated_s"] > 0


def test_model_compiled_looks_where_the_kernel_is_cached(tmp_path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """The compiled kernel lives in the user's cache folder ($BIAFC_CACHE_DIR), not beside the
    sources: a warm folder means no compile in the estimate, an empty one a compile (the
    estimate said 'compiled first: about 15 s' on every warm run)."""
    import sys

    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("BIAFC_CACHE_DIR", str(tmp_path))
    # this process may have loaded the kernel already: only the disk counts here
    monkeypatch.delitem(sys.modules, "sim_backend.dem.kernel", raising=False)
    assert not eta_mod.model_compiled()
    from sim_backend.dem.kernel_cache import kernel_index_folder

    write_fresh_index(kernel_index_folder() / "kernel.run_chunks-42.py311.nbi")
    assert eta_mod.model_compiled()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "elsewhere"))
    assert not eta_mod.model_compiled()


def test_the_first_point_of_a_cold_run_does_not_set_the_rate() -> None:
    """A second reader: on an empty compile cache the first point's 11 s (mostly the kernel's
    compile) became every point's rate until a second point of its kind: "ETA 02:49" with 4 s
    left."""
    costs = PointCosts(point_s=0.1, arm_s=0.0, basis="test", first_extra_s=12.0)
    eta = EtaEstimator(costs, [True] * 16)
    eta.measured(11.1)  # the compile and the first point
    assert eta.remaining_s() == pytest.approx(15 * 0.1)
    eta.measured(0.25)
    assert eta.remaining_s() == pytest.approx(14 * 0.25)
