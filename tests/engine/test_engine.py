"""The run engine on fake instruments: points, retries, failures, abort, pause, resume."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from daq.engine import EventKind, RunEngine, RunEvent, RunState
from protocols.runfile import PointState, read_run

from .fakes import SENS, FakeWorld, Faults, expected_velocity_m_per_s, fake_bench
from .helpers import make_protocol


def _run(protocol, bench, out, world=None, **kw):  # type: ignore[no-untyped-def]
    w = world or FakeWorld()
    eng = RunEngine(protocol, bench, fake_bench(w), out, **kw)
    events: list[RunEvent] = []
    eng.subscribe(events.append)
    res = eng.run()
    return eng, res, events, w


def test_complete_run_writes_every_point_in_m_per_s(protocol, bench, out: Path) -> None:
    eng, res, events, w = _run(protocol, bench, out)
    assert res.status == "complete", res.reason
    assert eng.state == RunState.COMPLETE
    run = read_run(out)
    assert run.status == "complete"
    assert set(run.scans) == {"ltr", "rtl"}
    assert run.attrs["protocol_yaml"] == protocol.text
    assert "generator" in run.snapshot and "stage" in run.snapshot
    ltr = run.scans["ltr"]
    assert ltr.velocity.shape == (2, 3, 220)
    assert np.all(ltr.done == PointState.DONE)
    assert ltr.amplitude_units == "V"
    # velocity (m/s) = volts * sensitivity, shifted back by the decoder delay
    positions = bench.bench.positions_m()
    t = ltr.time_s
    inner = slice(5, -5)
    for ai, vpp in enumerate([1.0, 2.0]):
        for ci in range(3):
            want = expected_velocity_m_per_s(1, vpp, positions[ci], t)
            err = ltr.velocity[ai, ci, inner] - want[inner]
            # noise 1e-4 V * SENS / sqrt(2 averages) ~ 3.5e-6 m/s rms
            assert np.std(err) < 3 * 1e-4 * SENS, (ai, ci)
            assert np.max(np.abs(want)) > 100 * np.std(err)
    kinds = [e.kind for e in events]
    assert kinds.count(EventKind.POINT_DONE) == 12
    assert kinds[-1] == EventKind.FINISHED
    progress = [e for e in events if e.kind == EventKind.PROGRESS]
    assert progress[-1].data["done"] == progress[-1].data["total"] == 12
    assert progress[-1].data["eta_s"] == 0
    # outputs off afterwards, one channel at a time during the run
    assert not any(w.outputs.values())
    assert w.triggers == 24


def test_a_decoder_delay_between_samples_is_undone_without_low_passing(
    protocol, bench, out: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The decoder's delay, a fraction of a sample (7.3 us at 100 kS/s), was undone by linear
    interpolation, which also low-passed the record: the 8 kHz signal came out 2-3 % small
    (``biafc calibrate`` read the stroke low by 12-28 of its standard errors)."""
    from . import fakes

    monkeypatch.setattr(fakes, "DELAY_S", 7.3e-6)
    _, res, _, _ = _run(protocol, bench, out)
    assert res.status == "complete", res.reason
    ltr = read_run(out).scans["ltr"]
    t, positions = ltr.time_s, bench.bench.positions_m()
    inner = slice(5, -5)
    want = expected_velocity_m_per_s(1, 2.0, positions[2], t)
    got = ltr.velocity[1, 2]
    err = got[inner] - want[inner]
    assert np.std(err) < 3 * 1e-4 * SENS, np.std(err) / np.std(want[inner])
    gain = float(np.dot(got[inner], want[inner]) / np.dot(want[inner], want[inner]))
    assert abs(gain - 1.0) < 1e-3, gain
    # the window's last samples too: the digitiser reads a tail past the window, so the
    # shift has data there (it held the last value: off by 2 pi f x delay, 4 % of the peak)
    assert np.max(np.abs(got[-5:] - want[-5:])) < 5 * 1e-4 * SENS


def test_a_signal_lost_while_averaging_fails_the_point_not_halves_it(
    protocol, bench, out: Path
) -> None:
    """The signal level was read once, before the records: a beam that lost the surface after
    the first of two records left the point "done" at half its velocity (a resume then kept
    it). It is read after every record too."""
    w = FakeWorld(faults=Faults(signal_lost_after_reads=1))
    _, res, _, _ = _run(protocol, bench, out, w)
    assert res.status != "complete"
    scan = read_run(out).scans[next(iter(read_run(out).scans))]
    assert scan.done.flat[0] == PointState.FAILED, scan.done
    assert not np.any(scan.done == PointState.DONE)
    assert any("signal level" in m and "after a record" in m for _, _, m in read_run(out).log)


def test_timeout_once_is_retried_and_the_run_completes(protocol, bench, out: Path) -> None:
    w = FakeWorld(faults=Faults(timeouts=1))
    _, res, events, _ = _run(protocol, bench, out, w)
    assert res.status == "complete"
    assert res.n_failed == 0
    run = read_run(out)
    assert np.all(run.scans["rtl"].done == PointState.DONE)
    assert any("InstrumentTimeout" in m for _, _, m in run.log)
    assert any(e.kind == EventKind.WARNING for e in events)


def test_point_failing_every_retry_is_marked_and_run_continues(protocol, bench, out: Path) -> None:
    w = FakeWorld(faults=Faults(nan_reads=3))  # first point: 3 attempts, all NaN
    _, res, events, _ = _run(protocol, bench, out, w)
    assert res.status == "failed" and res.points_failed_only  # not "complete" (issue 15)
    assert res.n_failed == 1
    done = read_run(out).scans["ltr"].done
    assert done[0, 0] == PointState.FAILED
    assert np.sum(done == PointState.DONE) == 5
    assert [e.kind for e in events].count(EventKind.POINT_FAILED) == 1


def test_on_point_failure_stop_fails_the_run(bench, out: Path) -> None:
    p = make_protocol(**{"on_point_failure: continue": "on_point_failure: stop"})
    w = FakeWorld(faults=Faults(clip=True))
    _, res, _, _ = _run(p, bench, out, w)
    assert res.status == "failed"
    assert "failed after 2 retries" in res.reason
    run = read_run(out)
    assert run.status == "failed"
    assert any("clipped" in m for _, _, m in run.log)


def test_stage_stall_fails_safely_with_a_clear_message(protocol, bench, out: Path) -> None:
    w = FakeWorld(faults=Faults(stall_on_move=2))
    _, res, events, _ = _run(protocol, bench, out, w)
    assert res.status == "failed"
    assert "StallError" in res.reason and "stalled" in res.reason
    assert not any(w.outputs.values())
    assert w.safe_calls >= 1
    run = read_run(out)
    assert run.status == "failed"
    assert np.sum(run.scans["ltr"].done == PointState.DONE) == 2
    assert any("stalled" in m for _, _, m in run.log)
    assert events[-1].data["status"] == "failed"


def test_abort_from_another_thread(protocol, bench, out: Path) -> None:
    w = FakeWorld(faults=Faults(read_sleep_s=0.02))
    eng = RunEngine(protocol, bench, fake_bench(w), out)
    first = threading.Event()
    eng.subscribe(lambda e: first.set() if e.kind == EventKind.POINT_DONE else None)
    eng.start()
    assert first.wait(10)
    eng.abort("stop requested")
    res = eng.wait(10)
    assert res is not None and res.status == "aborted"
    assert res.reason == "stop requested"
    assert not any(w.outputs.values())
    run = read_run(out)
    assert run.status == "aborted"
    n = int(np.sum(run.scans["ltr"].done == PointState.DONE))
    assert 1 <= n < 6
    assert any("aborted" in m for _, _, m in run.log)


def test_an_abort_while_the_stage_homes_stops_it_at_once(protocol, bench, out: Path) -> None:
    """Homing may take minutes on the rig; the run said nothing of it (the window showed "idle")
    and an abort waited for it to end. Now a status event names it, and an abort stops it."""
    import time

    w = FakeWorld(faults=Faults(home_s=30.0))
    eng = RunEngine(protocol, bench, fake_bench(w), out)
    homing = threading.Event()
    eng.subscribe(
        lambda e: (
            homing.set()
            if e.kind == EventKind.STATUS and e.data["text"] == "homing the stage"
            else None
        )
    )
    eng.start()
    assert homing.wait(10)
    t0 = time.monotonic()
    eng.abort("stop requested")
    res = eng.wait(10)
    assert res is not None and res.status == "aborted" and time.monotonic() - t0 < 5
    assert not w.homed and w.moves == 0


def test_pause_and_resume_at_point_boundaries(protocol, bench, out: Path) -> None:
    w = FakeWorld(faults=Faults(read_sleep_s=0.005))
    eng = RunEngine(protocol, bench, fake_bench(w), out)
    states: list[str] = []
    eng.subscribe(
        lambda e: states.append(e.data["state"]) if e.kind == EventKind.STATE_CHANGED else None
    )
    done_when_paused = threading.Event()

    def on_event(e: RunEvent) -> None:
        if e.kind == EventKind.POINT_DONE and not done_when_paused.is_set():
            eng.pause()
            done_when_paused.set()

    eng.subscribe(on_event)
    eng.start()
    assert done_when_paused.wait(10)
    reads = w.reads
    threading.Event().wait(0.3)
    assert eng.state == RunState.PAUSED
    assert w.reads == reads  # nothing measured while paused
    eng.resume()
    res = eng.wait(20)
    assert res is not None and res.status == "complete"
    assert "paused" in states and states[-1] == "complete"
    # the pause is in the run's file and log (the window, which recorded it, no longer does)
    said = [m for _, _, m in read_run(out).log]
    assert "run paused" in said
    assert any(m.startswith("run resumed after ") for m in said)


def test_resume_finishes_and_equals_an_uninterrupted_run(protocol, bench, tmp_path: Path) -> None:
    full = tmp_path / "full.h5"
    _run(protocol, bench, full, FakeWorld(seed=3), seed=3)
    part = tmp_path / "part.h5"
    _, res, _, _ = _run(
        protocol, bench, part, FakeWorld(seed=3, faults=Faults(stall_on_move=7)), seed=3
    )
    assert res.status == "failed"
    w2 = FakeWorld(seed=3)
    _, res2, events, _ = _run(protocol, bench, part, w2, resume=True, seed=3)
    assert res2.status == "complete", res2.reason
    assert events[0].kind == EventKind.STATE_CHANGED
    started = next(e for e in events if e.kind == EventKind.RUN_STARTED)
    assert started.data["n_todo"] == 12 - 7
    a, b = read_run(full), read_run(part)
    assert b.status == "complete"
    for d in ("ltr", "rtl"):
        np.testing.assert_array_equal(a.scans[d].velocity, b.scans[d].velocity)
        np.testing.assert_array_equal(a.scans[d].done, b.scans[d].done)
    assert any("resumed" in m for _, _, m in b.log)


def test_resume_refuses_another_protocol(protocol, bench, out: Path) -> None:
    _run(protocol, bench, out, FakeWorld(faults=Faults(stall_on_move=1)))
    other = make_protocol(**{"averages: 2": "averages: 3"})
    _, res, _, _ = _run(other, bench, out, resume=True)
    assert res.status == "refused"
    assert "another protocol" in res.reason


def test_a_subscriber_that_raises_never_stops_the_run(protocol, bench, out: Path) -> None:
    eng = RunEngine(protocol, bench, fake_bench(), out)

    def bad(e: RunEvent) -> None:
        raise RuntimeError("boom")

    eng.subscribe(bad)
    assert eng.run().status == "complete"


def test_engine_runs_once(protocol, bench, out: Path) -> None:
    eng = RunEngine(protocol, bench, fake_bench(), out)
    assert eng.run().status == "complete"
    with pytest.raises(RuntimeError, match="runs once"):
        eng.run()
    assert read_run(out).status == "complete"


def test_a_bench_fault_that_fails_every_point_ends_the_run_after_a_few(bench, out: Path) -> None:
    """The trigger never arrives (every read times out): each point failed its 3 attempts and
    the run went on to the end, at the default 10 s read timeout 30 s a point, 20 hours for
    2,480 points, with the generator driving the piezo all along. Now the run ends failed after
    ``max_failed_in_a_row`` failed points, safe, the rest pending for --resume."""
    p = make_protocol(**{"retries: 2": "retries: 2\nmax_failed_in_a_row: 3"})
    w = FakeWorld(faults=Faults(timeouts=10_000))
    _, res, _, _ = _run(p, bench, out, w)
    assert res.status == "failed" and not res.points_failed_only
    assert res.n_failed == 3
    assert "3 points in a row failed (max_failed_in_a_row)" in res.reason
    assert f"--resume {out}" in res.reason
    assert res.safe_state_s is not None and not any(w.outputs.values())
    run = read_run(out)
    assert run.status == "failed"
    done = np.concatenate([s.done.ravel() for s in run.scans.values()])
    assert np.sum(done == PointState.FAILED) == 3 and np.sum(done == PointState.PENDING) == 9
    assert 10_000 - w.faults.timeouts == 3 * 3  # 3 points x 3 attempts, each read timed out


def test_failed_points_apart_do_not_end_the_run(bench, out: Path) -> None:
    """Two points in a row fail, then the bench measures again: the count starts over."""
    p = make_protocol(**{"retries: 2": "retries: 2\nmax_failed_in_a_row: 3"})
    w = FakeWorld(faults=Faults(timeouts=6))  # 2 points x 3 attempts
    _, res, _, _ = _run(p, bench, out, w)
    assert res.status == "failed" and res.points_failed_only and res.n_failed == 2


def test_max_failed_in_a_row_is_bounded_in_one_line() -> None:
    from protocols.yamlfile import ConfigError

    with pytest.raises(ConfigError) as err:
        make_protocol(**{"retries: 2": "retries: 2\nmax_failed_in_a_row: -1"})
    assert "max_failed_in_a_row" in str(err.value) and "\n" not in str(err.value)
    assert make_protocol().protocol.max_failed_in_a_row == 10
    assert make_protocol(**{"retries: 2": "retries: 2\nmax_failed_in_a_row: 0"})


def test_a_run_whose_stored_protocol_names_no_h5_output_can_still_be_resumed(
    bench, tmp_path: Path
) -> None:
    """New protocols' output patterns must end in .h5 (a run's log is NAME.log beside it); a
    run made before that rule stores its protocol with an older pattern, and was refused on
    --resume ("the request stored ... is unreadable") until the rule applied to new files only
    (found by a second reader)."""
    from daq.request import validate_request

    from .helpers import PROTOCOL

    old = make_protocol(PROTOCOL + 'output: "runs/{name}_{timestamp}.hdf5"\n')
    assert old.protocol.output.endswith(".hdf5")
    out = tmp_path / "old.h5"
    _, res, _, _ = _run(old, bench, out, FakeWorld(faults=Faults(stall_on_move=3)))
    assert res.status == "failed"
    req = validate_request(resume=out)
    assert req.resume and req.out == out
