"""End to end on the simulated bench (real drivers on the emulated instruments, DEM world):
smoke.yaml makes a complete run file whose velocities reproduce the DEM; injected faults;
abort with the generator's output off on the emulator."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from daq.cli import run_protocol as rp
from daq.connect import connect_bench
from daq.engine import EventKind, RunEngine, RunEvent
from protocols.bench import load_bench
from protocols.runfile import PointState, read_run
from protocols.schema import load_protocol
from protocols.swmr_read import open_swmr

ROOT = Path(__file__).resolve().parents[2] / "protocols"


def _generator_outputs_off(inst) -> bool:  # type: ignore[no-untyped-def]
    """Ask the emulated 33500B itself (``OUTPn?``), not the driver's bookkeeping."""
    transport = inst.generator.transport
    return all(transport.query(f"OUTP{ch}?").strip() == "0" for ch in (1, 2))


def test_smoke_reproduces_the_dem(tmp_path: Path) -> None:
    from sim_backend import dem

    out = tmp_path / "smoke.h5"
    assert rp.main([str(ROOT / "smoke.yaml"), "--out", str(out), "--quiet"]) == 0
    run = read_run(out)
    assert run.status == "complete" and run.backend == "sim"
    # provenance: the instruments said who they are
    assert run.snapshot["generator"]["identity"].startswith("Keysight Technologies,")
    assert "OFV-5000" in run.snapshot["vibrometer"]["identity"]
    scan = run.scans["ltr"]
    assert np.all(scan.done == PointState.DONE)
    assert scan.amplitude_units == "m"
    chain = dem.build_chain(dem.default_chain_spec())
    proto = load_protocol(ROOT / "smoke.yaml").protocol
    t = scan.time_s
    res = dem.simulate(
        chain,
        [
            dem.Drive(
                direction="ltr",
                kind="displacement",
                amplitude=float(a),
                burst=proto.burst["ltr"].burst(),
            )
            for a in scan.amplitudes
        ],
        duration_s=0.03,
        sample_rate_Hz=scan.sample_rate_Hz,
    )
    after = t >= 0
    for ai in range(len(scan.amplitudes)):
        for ci, cyl in enumerate(scan.cylinders):
            want = np.interp(t[after], res.time_s, res.velocity[ai, cyl - 1])
            got = scan.velocity[ai, ci, after]
            err = np.sqrt(np.mean((got - want) ** 2))
            assert err < 0.01 * np.max(np.abs(want)) + 3e-5, (ai, cyl, err)


def _engine(tmp_path: Path, faults: dict) -> tuple[RunEngine, object]:
    pf = load_protocol(ROOT / "smoke.yaml")
    bf = load_bench()
    inst = connect_bench(bf, faults=faults)
    return RunEngine(pf, bf, inst, tmp_path / "run.h5"), inst


def test_timeout_once_is_retried(tmp_path: Path) -> None:
    eng, inst = _engine(tmp_path, {"digitiser_timeout": True, "after_acquisitions": 2})
    world = inst.world  # type: ignore[attr-defined]

    def clear_on_warning(e: RunEvent) -> None:
        if e.kind == EventKind.WARNING and "Timeout" in e.message:
            world.faults.clear()

    eng.subscribe(clear_on_warning)
    res = eng.run()
    assert res.status == "complete", res.reason
    assert res.n_failed == 0
    assert any("InstrumentTimeout" in m for _, _, m in read_run(eng.out_path).log)


def test_stage_stall_aborts_safely(tmp_path: Path) -> None:
    eng, inst = _engine(tmp_path, {"stage_stall": True})
    res = eng.run()
    assert res.status == "failed"
    assert "stall" in res.reason.lower()
    assert read_run(eng.out_path).status == "failed"
    assert _generator_outputs_off(inst)


def test_abort_from_a_thread_turns_the_generator_off(tmp_path: Path) -> None:
    eng, inst = _engine(tmp_path, {})
    first = threading.Event()
    eng.subscribe(lambda e: first.set() if e.kind == EventKind.POINT_DONE else None)
    eng.subscribe(lambda e: eng.abort("test abort") if e.kind == EventKind.POINT_DONE else None)
    res = eng.run()
    assert first.is_set()
    assert res.status == "aborted"
    assert read_run(eng.out_path).status == "aborted"
    assert _generator_outputs_off(inst)


def test_sigkill_then_resume_on_the_sim_bench(tmp_path: Path) -> None:
    import os
    import subprocess
    import sys
    import time

    bench = tmp_path / "slow_bench.yaml"
    bench.write_text(load_bench().text.replace("speedup: 0 ", "speedup: 20 "))
    args = [str(ROOT / "smoke.yaml"), "--bench", str(bench), "--seed", "7", "--quiet"]
    killed = tmp_path / "killed.h5"
    proc = subprocess.Popen(
        [sys.executable, "-m", "daq.cli.run_protocol", *args, "--out", str(killed)],
        cwd=ROOT.parent, env=dict(os.environ), stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    t_end = time.monotonic() + 120
    n = 0
    while n < 2 and time.monotonic() < t_end:
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
        try:
            with open_swmr(killed) as f:
                n = int(np.sum(f["scan/ltr/done"][...] == PointState.DONE))
        except (OSError, KeyError):
            pass
    proc.kill()
    proc.wait(10)
    part = read_run(killed)
    done = part.scans["ltr"].done == PointState.DONE
    assert 2 <= done.sum() < done.size, "kill the run mid-scan"
    assert np.all(np.isfinite(part.scans["ltr"].velocity[done]))
    assert rp.main([*args, "--resume", str(killed)]) == 0
    full = tmp_path / "full.h5"
    assert rp.main([str(ROOT / "smoke.yaml"), "--seed", "7", "--quiet", "--out", str(full)]) == 0
    a, b = read_run(full).scans["ltr"], read_run(killed).scans["ltr"]
    np.testing.assert_array_equal(a.done, b.done)
    np.testing.assert_array_equal(a.velocity, b.velocity)


def test_sigint_aborts_and_the_emulated_generator_is_off(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import os
    import signal
    import time

    import daq.connect

    made: list = []
    real = daq.connect.connect_bench

    def keep(*a, **k):  # type: ignore[no-untyped-def]
        made.append(real(*a, **k))
        return made[-1]

    monkeypatch.setattr(daq.connect, "connect_bench", keep)
    bench = tmp_path / "slow_bench.yaml"
    bench.write_text(load_bench().text.replace("speedup: 0 ", "speedup: 20 "))
    out = tmp_path / "int.h5"

    def interrupt_after_first_point() -> None:
        t_end = time.monotonic() + 60
        while time.monotonic() < t_end:
            try:
                with open_swmr(out) as f:
                    if f["scan/ltr/done"][...].sum() >= 1:
                        break
            except (OSError, KeyError):
                pass
            time.sleep(0.02)
        os.kill(os.getpid(), signal.SIGINT)

    threading.Thread(target=interrupt_after_first_point, daemon=True).start()
    code = rp.main([str(ROOT / "smoke.yaml"), "--bench", str(bench), "--out", str(out), "--quiet"])
    assert code == 130
    run = read_run(out)
    assert run.status == "aborted"
    assert any("SIGINT" in m for _, _, m in run.log)
    world = made[0].world
    gen = world.transport("generator")
    assert [gen.query(f"OUTP{ch}?").strip() for ch in (1, 2)] == ["0", "0"]


def test_a_silent_generator_ends_unsafe_and_the_emulator_output_is_really_on(
    tmp_path: Path,
) -> None:
    """Issue 15: the emulated 33500B stops answering after the 3rd record; its output stays
    on, so the run must say ``unsafe`` (not "complete"), at once and naming the generator."""
    eng, inst = _engine(tmp_path, {"generator_silent": True, "after_acquisitions": 3})
    res = eng.run()
    assert res.status == "unsafe", res.reason
    assert "stopped answering" in res.reason
    assert any(u.startswith("generator (simulated) output 1") for u in res.unconfirmed)
    assert res.n_failed == 0  # not every retry of every point spent on timeouts
    assert read_run(eng.out_path).status == "unsafe"
    inst.world.faults.clear()  # type: ignore[attr-defined]
    assert not _generator_outputs_off(inst)  # it really is still on


def test_a_generator_error_during_the_last_point_is_not_complete(tmp_path: Path) -> None:
    """Issue 15 (found by the fault campaign): an SCPI error queued while the last point
    played was never read and the run ended "complete"; the queue is read after every point."""
    eng, _ = _engine(tmp_path, {"generator_scpi_error": '-222,"Data out of range"',
                                "after_acquisitions": 10})  # fmt: skip
    res = eng.run()
    assert res.status == "failed", res.reason
    assert "-222" in res.reason
    assert read_run(eng.out_path).status == "failed"


def test_a_stage_too_slow_for_its_move_is_not_called_a_dead_link(tmp_path: Path) -> None:
    """A second reader: a move that outlasted its bound while the controller answered every
    poll ended the run "DeadInstrumentError: stage stopped answering", sending the person to
    the cable when the axis was blocked or slow."""
    eng, inst = _engine(tmp_path, {})
    emu = inst.world._inst.stage  # type: ignore[attr-defined]
    real_go = emu._go
    emu._go = lambda target, maxspeed=None: real_go(target, 100)  # a blocked, slow axis
    res = eng.run()
    assert res.status == "failed", res.reason
    assert "MoveTimeout" in res.reason and "controller answered" in res.reason
    assert "stopped answering" not in res.reason
    assert _generator_outputs_off(inst)
