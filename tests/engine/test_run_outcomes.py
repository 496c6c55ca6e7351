"""Runs that never lie (issue 15): an unconfirmed safe state is ``unsafe`` (exit 3) and names
what to switch off; a dead instrument stops the run at once; failed points are not "complete"
(exit 4) and a resume re-measures them; refusals are exit 2 (another protocol, another bench,
a file another process writes); Ctrl-C is clean from the first moment."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

import daq.connect
from daq.cli import run_protocol as rp
from daq.engine import RunEngine
from daq.engine.outcome import ExitCode
from daq.store.lock import lock_path
from protocols.runfile import PointState, read_run

from .fakes import FakeWorld, Faults, fake_bench
from .helpers import PROTOCOL
from .test_cli import _spawn, _wait_done


def _use(monkeypatch: pytest.MonkeyPatch, *worlds: FakeWorld) -> list[FakeWorld]:
    """The next assemblies get these worlds, in turn (seeded as the CLI asks)."""
    queue = list(worlds)
    used: list[FakeWorld] = []

    def connect_bench(bf, seed=None, **k):  # type: ignore[no-untyped-def]
        w = queue.pop(0) if queue else FakeWorld()
        w.seed = seed or 0
        used.append(w)
        return fake_bench(w)

    monkeypatch.setattr(daq.connect, "connect_bench", connect_bench)
    return used


def _last_err(capsys: pytest.CaptureFixture[str]) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    return lines[-1] if lines else ""


# -- safe state ------------------------------------------------------------------------------
def test_a_generator_that_stops_answering_ends_unsafe_at_once(protocol, bench, out) -> None:
    w = FakeWorld(faults=Faults(generator_dead_after_reads=4))  # dies after point 2 of 12
    eng = RunEngine(protocol, bench, fake_bench(w), out)
    res = eng.run()
    gen = eng.instruments.generator
    assert res.status == "unsafe"
    assert w.outputs[1] is True  # the lost OUTP1 OFF really left it on
    assert any("output 1" in u and "generator" in u for u in res.unconfirmed)
    assert res.safe_state_s is None
    # detected at once (its error queue, read after point 2, gets no reply), then one
    # read-back; no point spent on retries or marked failed, point 2 is measured again later
    assert "stopped answering" in res.reason
    assert res.n_failed == 0 and res.n_measured_now == 1
    assert gen.queries <= 2  # type: ignore[attr-defined]
    run = read_run(out)
    assert run.status == "unsafe"
    outcome = run.attrs["outcome"]  # with what to switch off, as the last line (a reviewer)
    assert outcome.startswith("run UNSAFE (safe state not confirmed after the run")
    assert "SWITCH OFF BY HAND" in outcome and "output 1" in outcome
    assert any("SWITCH OFF BY HAND" in m and "output 1" in m for _, _, m in run.log)


def test_cli_unsafe_end_is_exit_3_with_a_last_line_naming_the_generator(
    proto_file, tmp_path, capsys, monkeypatch
) -> None:
    _use(monkeypatch, FakeWorld(faults=Faults(generator_dead_after_reads=4)))
    code = rp.main([str(proto_file), "--out", str(tmp_path / "u.h5"), "--quiet"])
    assert code == ExitCode.UNSAFE == 3
    last = _last_err(capsys)
    assert last.startswith("run UNSAFE") and "SWITCH OFF BY HAND" in last
    assert "generator" in last and "output 1" in last


def test_the_safe_state_is_confirmed_by_reading_the_outputs_back(protocol, bench, out) -> None:
    res = RunEngine(protocol, bench, fake_bench(FakeWorld()), out).run()
    assert res.status == "complete" and res.safe_state_s is not None
    assert any("safe state confirmed" in m for _, _, m in read_run(out).log)
    assert read_run(out).attrs["outcome"] == "complete"


def test_a_stage_still_moving_after_stop_is_an_unconfirmed_safe_state(protocol, bench, out) -> None:
    """The safe state asks the stage whether its axis came to rest (Zaber: BUSY while it
    decelerates); before, only the generator's outputs were read back."""
    w = FakeWorld(faults=Faults(stage_keeps_moving=True))
    res = RunEngine(protocol, bench, fake_bench(w), out).run()
    assert res.status == "unsafe" and res.safe_state_s is None
    assert res.unconfirmed == ("stage controller: the axis still moves after 'stop'",)
    said = [m for _, _, m in read_run(out).log if "SWITCH OFF BY HAND" in m]
    assert said == [
        "SWITCH OFF BY HAND: stage controller: the axis still moves after 'stop' before "
        "reaching into the stage's travel"
    ]  # not the piezo amplifier's advice: the outputs were confirmed off


# -- failed points ---------------------------------------------------------------------------
def test_failed_points_are_exit_4_and_a_resume_remeasures_them(
    proto_file, tmp_path, capsys, monkeypatch
) -> None:
    _use(monkeypatch, FakeWorld(faults=Faults(nan_reads=3)), FakeWorld(), FakeWorld())
    part, full = tmp_path / "part.h5", tmp_path / "full.h5"
    assert rp.main([str(proto_file), "--out", str(part), "--quiet", "--seed", "4"]) == 4
    err = capsys.readouterr().err
    last = err.strip().splitlines()[-1]
    assert "1 of 12 points failed" in last and "--resume" in last
    # the run's log and its warnings say it as the last line does (a second reader)
    log = part.with_suffix(".log").read_text()
    assert "run failed" not in err + log and "finished with failed points: 1 of 12" in log
    # the last line and the file tell it from a run that failed (a second reader: both read
    # "run failed: ...", and the file held status "failed" only)
    assert last.startswith("finished with failed points: 1 of 12 points failed")
    assert read_run(part).status == "failed"
    assert read_run(part).attrs["outcome"].startswith("finished with failed points: 1 of 12")
    # a resume removes the earlier outcome until its own close; one killed before then and
    # repaired says so (a reviewer: status aborted beside "finished with failed points")
    copy = tmp_path / "killed.h5"
    copy.write_bytes(part.read_bytes())
    from daq.store.repair import repair_run
    from protocols.runfile import RunFileWriter

    RunFileWriter.open_existing(copy, resumed=True)  # never closed: a resume killed
    assert "outcome" not in read_run(copy).attrs
    repair_run(copy)
    killed = read_run(copy)
    assert killed.status == "aborted" and killed.attrs["outcome"].endswith("(repaired)")
    # the dry run of the resume says what it will measure, not the whole plan (12 points)
    assert rp.main([str(proto_file), "--resume", str(part), "--dry-run"]) == 0
    assert ": 1 of 12 points to measure, estimated" in capsys.readouterr().out
    assert rp.main([str(proto_file), "--resume", str(part), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "measured now 1, already in the file 11, failed 0" in out
    assert rp.main([str(proto_file), "--out", str(full), "--quiet", "--seed", "4"]) == 0
    a, b = read_run(full), read_run(part)
    assert b.status == "complete"
    # the resume's seed is kept with the resume (the root's stays the start's)
    assert json.loads(b.attrs["resumes_json"])[-1]["seed"] == 4
    for d in ("ltr", "rtl"):
        assert np.all(b.scans[d].done == PointState.DONE)
        np.testing.assert_array_equal(a.scans[d].velocity, b.scans[d].velocity)


# -- refusals --------------------------------------------------------------------------------
def test_a_refused_resume_is_exit_2_not_a_failed_run(
    proto_file, tmp_path, capsys, monkeypatch
) -> None:
    _use(monkeypatch, FakeWorld(faults=Faults(stall_on_move=1)), FakeWorld())
    f = tmp_path / "r.h5"
    assert rp.main([str(proto_file), "--out", str(f), "--quiet"]) == 1
    capsys.readouterr()
    other = tmp_path / "other.yaml"
    other.write_text(PROTOCOL.replace("averages: 2", "averages: 3"))
    assert rp.main([str(other), "--resume", str(f), "--quiet"]) == 2
    last = _last_err(capsys)
    assert "refused" in last and "another protocol" in last and "unexpected" not in last
    assert read_run(f).status == "failed"  # untouched


def test_a_resume_on_another_bench_is_refused_with_the_differences(
    proto_file, tmp_path, capsys, monkeypatch
) -> None:
    from protocols.bench import load_bench

    _use(monkeypatch, FakeWorld(faults=Faults(stall_on_move=1)), FakeWorld())
    f = tmp_path / "b.h5"
    assert rp.main([str(proto_file), "--out", str(f), "--quiet"]) == 1
    capsys.readouterr()
    other = tmp_path / "gain40.yaml"
    text = load_bench().text
    other.write_text(text.replace("gain: 20 ", "gain: 40 ").replace("ai0", "ai2"))
    args = [str(proto_file), "--bench", str(other), "--resume", str(f), "--quiet"]
    assert rp.main(args) == 2
    last = _last_err(capsys)
    assert "another bench" in last and "amplifier.gain: 20 in" in last and "40 now" in last
    assert "daq.velocity_channel" in last
    assert int(np.sum(read_run(f).scans["ltr"].done == PointState.DONE)) == 1  # untouched
    assert rp.main([*args, "--accept-bench-change"]) == 0
    run = read_run(f)
    overrides = json.loads(run.attrs["bench_overrides_json"])
    assert "amplifier.gain" in overrides[0]["differences"][0]
    assert "gain: 40" in overrides[0]["bench_yaml"]
    assert any("different bench" in m for _, _, m in run.log)


def test_a_second_writer_is_refused_and_the_first_run_completes(
    proto_file, tmp_path, capsys, monkeypatch
) -> None:
    f = tmp_path / "busy.h5"
    proc = _spawn([str(proto_file), "--out", str(f), "--seed", "2"], read_s=0.04)
    try:
        _wait_done(f, 1, proc)
        _use(monkeypatch, FakeWorld())
        assert rp.main([str(proto_file), "--resume", str(f), "--quiet"]) == 2
        last = _last_err(capsys)
        assert f"process {proc.pid} on {socket.gethostname()}" in last
        _, stderr = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, stderr
    run = read_run(f)
    assert run.status == "complete"
    assert all(np.all(s.done == PointState.DONE) for s in run.scans.values())
    assert not lock_path(f).exists()


def test_a_stale_lock_of_a_dead_process_is_taken_over(
    proto_file, tmp_path, capsys, monkeypatch
) -> None:
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    f = tmp_path / "stale.h5"
    lock_path(f).write_text(json.dumps({"host": socket.gethostname(), "pid": dead.pid}))
    _use(monkeypatch, FakeWorld())
    assert rp.main([str(proto_file), "--out", str(f), "--quiet"]) == 0
    assert any("stale lock" in m for _, _, m in read_run(f).log)
    assert not lock_path(f).exists()


# -- Ctrl-C ----------------------------------------------------------------------------------
def test_ctrl_c_while_connecting_is_clean_and_immediate(proto_file, tmp_path) -> None:
    out = tmp_path / "c.h5"
    env_extra = {"FAKE_CONNECT_S": "30"}
    os.environ.update(env_extra)
    try:
        proc = _spawn([str(proto_file), "--out", str(out)])
    finally:
        os.environ.pop("FAKE_CONNECT_S")
    time.sleep(1.5)  # imports done, inside the (slow) bench assembly
    t0 = time.monotonic()
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=20)
    assert time.monotonic() - t0 < 5
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    assert "nothing was switched on" in stderr.strip().splitlines()[-1]
    assert not out.exists()


def test_ctrl_c_during_the_run_shows_the_time_to_the_safe_state(proto_file, tmp_path) -> None:
    out = tmp_path / "i.h5"
    proc = _spawn([str(proto_file), "--out", str(out)])
    _wait_done(out, 1, proc)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=30)
    assert proc.returncode == 130, stderr
    last = stderr.strip().splitlines()[-1]
    assert last.startswith("run aborted: interrupted by SIGINT")
    assert "safe state confirmed in" in last
    assert "OUTPUTS {1: False, 2: False}" in stdout


def test_ctrl_c_during_a_point_that_hangs_is_bounded(proto_file, tmp_path) -> None:
    """A read that takes 30 s (a DEM compiling, a stage homing): the first Ctrl-C asks for an
    abort at the next boundary; after the bound the run is interrupted where it is."""
    out = tmp_path / "h.h5"
    os.environ["FAKE_ABORT_BOUND_S"] = "1"
    try:
        proc = _spawn([str(proto_file), "--out", str(out)], read_s=30)
    finally:
        os.environ.pop("FAKE_ABORT_BOUND_S")
    t_end = time.monotonic() + 30
    while not out.exists() and time.monotonic() < t_end:
        time.sleep(0.05)
    time.sleep(0.3)  # inside the first (hanging) read
    t0 = time.monotonic()
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=30)
    assert time.monotonic() - t0 < 5
    assert proc.returncode == 130, stderr
    assert "the run stops within 1 s and the safe state follows" in stderr
    assert "safe state confirmed in" in stderr.strip().splitlines()[-1]
    assert "OUTPUTS {1: False, 2: False}" in stdout


def test_a_vibrometer_that_stops_answering_stops_the_run_at_once(
    protocol, bench, out, monkeypatch
) -> None:
    from instruments.errors import InstrumentTimeout

    from .fakes import FakeVibrometer

    asked: list[int] = []

    def silent(self) -> float:  # type: ignore[no-untyped-def]
        asked.append(1)
        if len(asked) > 6:  # asked before a point's first record and after each of its two
            raise InstrumentTimeout("vibrometer: no reply to 'Get,Controller,0,SignalLevel'")
        return 0.9

    monkeypatch.setattr(FakeVibrometer, "signal_level", silent)
    res = RunEngine(protocol, bench, fake_bench(FakeWorld()), out).run()
    assert res.status == "failed" and "vibrometer stopped answering" in res.reason
    assert len(asked) == 7  # not three timeouts per point for every point left
    assert res.n_failed == 0 and res.n_measured_now == 2
    assert res.safe_state_s is not None  # the generator confirmed its outputs off


def test_in_use_by_names_a_live_writer_and_ignores_a_dead_one(tmp_path) -> None:
    from daq.store.lock import in_use_by

    f = tmp_path / "x.h5"
    assert in_use_by(f) is None
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        lock_path(f).write_text(json.dumps({"host": socket.gethostname(), "pid": live.pid}))
        assert f"process {live.pid}" in (in_use_by(f) or "")
    finally:
        live.kill()
        live.wait()
    assert in_use_by(f) is None


def test_a_resume_after_the_chain_file_was_edited_is_refused_naming_the_chain(
    proto_file, tmp_path, capsys
) -> None:
    """The bench names its chain by path: with the chain file edited between the start and a
    resume, the bench's text was unchanged, the resume ran on the new chain and one file held
    points of two chains under the first one's /chain (a second reader's fault campaign)."""
    from pathlib import Path

    import sim_backend.dem
    from protocols.bench import default_bench_path

    chain = Path(sim_backend.dem.__file__).parent / "chains" / "default.yaml"
    (tmp_path / "mychain.yaml").write_text(chain.read_text())
    text = default_bench_path().read_text().replace("chain: null", "chain: mychain.yaml")
    bench = tmp_path / "bench.yaml"
    bench.write_text(text)
    failing = tmp_path / "failing.yaml"  # the stage stalls after two records
    failing.write_text(
        text.replace("faults: {}", "faults: {stage_stall: true, after_acquisitions: 4}")
    )
    f = tmp_path / "mix.h5"
    assert rp.main([str(proto_file), "--bench", str(failing), "--out", str(f), "-q"]) == 1
    done = int(np.sum(read_run(f).scans["ltr"].done == PointState.DONE))
    assert done >= 1
    edited = (tmp_path / "mychain.yaml").read_text().replace("13.6 mm", "12 mm")
    (tmp_path / "mychain.yaml").write_text(edited)
    capsys.readouterr()
    args = [str(proto_file), "--bench", str(bench), "--resume", str(f), "-q"]
    assert rp.main(args) == 2
    last = _last_err(capsys)
    assert "another bench" in last and "chain diameter: '13.6 mm' in" in last, last
    assert "'12 mm' now (chain file mychain.yaml)" in last, last
    assert int(np.sum(read_run(f).scans["ltr"].done == PointState.DONE)) == done  # untouched
    assert rp.main([*args, "--accept-bench-change"]) == 0
    overrides = json.loads(read_run(f).attrs["bench_overrides_json"])
    assert any(d.startswith("chain diameter") for d in overrides[0]["differences"])


def test_a_run_refused_at_the_files_lock_writes_nothing_into_its_log(
    proto_file, tmp_path, capsys, monkeypatch
) -> None:
    """Two runs started at once on one file both pass the request's checks; the one refused at
    the run file's lock wrote its "starting" and "refused" lines into the other's RUN.log. The
    log opens only once the run file is this process's."""
    from daq.logsetup import log_path_for
    from daq.store.lock import RunFileLock

    f = tmp_path / "race.h5"
    held: list[RunFileLock] = []

    def other_wins(bf, seed=None, **k):  # type: ignore[no-untyped-def]
        held.append(RunFileLock(f).acquire())  # the other run, after this one's checks
        return fake_bench(FakeWorld())

    monkeypatch.setattr(daq.connect, "connect_bench", other_wins)
    try:
        assert rp.main([str(proto_file), "--out", str(f), "--quiet"]) == 2
        assert "refused" in _last_err(capsys)
        assert not log_path_for(f).exists()
    finally:
        held[0].release()
    _use(monkeypatch, FakeWorld())
    assert rp.main([str(proto_file), "--out", str(f), "--quiet"]) == 0
    text = log_path_for(f).read_text()
    assert text.count("starting") == 1 and "(exit 2)" not in text and "(exit 0)" in text


def test_an_instrument_that_does_not_answer_at_connect_is_exit_1_not_a_refusal(
    proto_file, tmp_path, capsys, monkeypatch
) -> None:
    from daq.logsetup import log_path_for
    from instruments.errors import InstrumentTimeout

    def dead(bf, seed=None, **k):  # type: ignore[no-untyped-def]
        raise InstrumentTimeout("generator (TCPIP0::1.2.3.4::INSTR): no reply to '*IDN?'")

    monkeypatch.setattr(daq.connect, "connect_bench", dead)
    f = tmp_path / "dead.h5"
    assert rp.main([str(proto_file), "--out", str(f), "--quiet"]) == 1
    last = _last_err(capsys)
    assert last.startswith("run_protocol: cannot connect the bench: generator (TCPIP0"), last
    assert last.endswith("nothing was switched on, no file written")
    assert not f.exists(), "file"
    assert not log_path_for(f).exists(), log_path_for(f).read_text()
    # a driver that is not installed is the installation's problem: refused, exit 2, as before
    from instruments.errors import DriverNotInstalledError

    def no_driver(bf, seed=None, **k):  # type: ignore[no-untyped-def]
        raise DriverNotInstalledError("digitiser: NI-DAQmx is not installed")

    monkeypatch.setattr(daq.connect, "connect_bench", no_driver)
    assert rp.main([str(proto_file), "--out", str(f), "--quiet"]) == 2
    assert "NI-DAQmx is not installed" in _last_err(capsys)


def test_out_naming_a_file_another_run_writes_says_so_not_resume_it(tmp_path) -> None:
    """'--out X' on a file another live process is writing said 'a run left running: continue
    it with --resume', which would then be refused; and the lock's message cut the holder's
    command at 80 characters, before the file's name (a second reader)."""
    from daq.store import StoreError, check_output_path
    from daq.store.lock import RunFileLock

    from .helpers import chain_info

    f = tmp_path / ("a_long_folder_name_" * 4) / "busy.h5"
    f.parent.mkdir()
    from protocols.runfile import RunFileWriter, ScanSpec

    spec = ScanSpec("ltr", np.array([1.0]), "V", np.array([1], np.int32), np.arange(4) / 1e5,
                    8920.0, 5.0, None)  # fmt: skip
    w = RunFileWriter.create(f, backend="sim", chain=chain_info(), scans=[spec])
    lock = RunFileLock(f).acquire()
    try:
        with pytest.raises(StoreError) as err:
            check_output_path(f)
        text = str(err.value)
        assert "is being written by process" in text and "left running" not in text
    finally:
        lock.release()
        w.close("aborted")


def test_an_unsafe_end_after_failed_points_still_says_unsafe_and_what_to_switch_off() -> None:
    """A reviewer: the outcome checked "finished with failed points" before "unsafe", so such a
    run's last line, the window and the file lost UNSAFE and SWITCH OFF BY HAND."""
    from types import SimpleNamespace

    from daq.engine.outcome import exit_code, final_line, outcome_text

    result = SimpleNamespace(
        status="unsafe", reason="safe state not confirmed after the run ended failed: "
        "finished with failed points: 2 of 10 points failed", points_failed_only=True,
        unconfirmed=("generator output 1",), safe_state_s=None, path="r.h5",
    )  # fmt: skip
    assert exit_code(result) == ExitCode.UNSAFE
    for text in (final_line(result), outcome_text(result)):
        assert text.startswith("run UNSAFE (") and "SWITCH OFF BY HAND: generator output 1" in text


def test_an_abort_before_the_file_is_made_says_no_file_was_written(protocol, bench, out) -> None:
    """A second reader (the window): an abort that landed before the run made its file ended
    with "(file RUN.h5)", naming a file that was never written."""
    from daq.engine.outcome import final_line

    eng = RunEngine(protocol, bench, fake_bench(FakeWorld()), out)
    eng.abort("aborted by the user")  # before the run reached its file
    res = eng.run()
    assert res.status == "aborted" and not out.exists()
    assert res.file_written is False
    line = final_line(res)
    assert f"no file written: {out} was not made" in line and f"(file {out})" not in line
    resumed = RunEngine(protocol, bench, fake_bench(FakeWorld()), out, resume=True)
    resumed.abort("aborted by the user")
    res = resumed.run()
    assert res.resumed and not res.file_written
    assert f"(file {out} not opened: unchanged)" in final_line(res)
