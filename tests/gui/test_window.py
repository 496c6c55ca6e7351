"""The bench window, offscreen: a run to completion, pause/resume/abort from the buttons,
validation errors, responsiveness, close during a run, browsing a run file. Screenshots of
the window mid-run and after a finished run go to $BIAFC_SCREENSHOTS (docs/screenshots to
refresh the docs) or a temporary folder."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from daq.connect import connect_bench
from daq.gui.main_window import MainWindow
from protocols.runfile import PointState, read_run

from .conftest import SMOKE, StallProbe, connect, make_assembler, wait_until

#: the event loop may not be blocked longer than this during a run (ms)
MAX_STALL_MS = 250.0


def _done_count(path: Path) -> int:
    run = read_run(path)
    return sum(int((s.done == PointState.DONE).sum()) for s in run.scans.values())


def test_smoke_run_to_completion(
    qtbot: Any, window: MainWindow, tmp_path: Path, screenshots: Path
) -> None:
    win = window
    assert win.protocol_panel.valid, win.protocol_panel.status_label.text()
    assert "6 points" in win.protocol_panel.status_label.text()
    connect(qtbot, win)
    assert win.bench_panel.tree.topLevelItemCount() >= 4  # each instrument's state shown
    probe = StallProbe()
    probe.start()
    shot_mid = False
    with qtbot.waitSignal(win.run_finished, timeout=120_000) as blocker:
        win.run_panel.start_button.click()
        while not win.last_result and not shot_mid:
            qtbot.wait(20)
            if win.live.n_points >= 3 and not shot_mid and win.running:
                qtbot.wait(150)  # let a redraw happen
                probe.pause()  # the test's own screenshot blocks the loop; not the window's
                assert win.grab().save(str(screenshots / "bench_window_mid_run.png"))
                probe.start()
                shot_mid = True
    longest = probe.stop()
    assert blocker.args == ["complete"]
    qtbot.wait(150)
    # the views hold data
    assert win.views.trace.n_drawn > 100
    assert win.views.spectrum.n_drawn > 10
    assert win.views.spatial.n_rows == 3  # smoke: cylinders 1, 8, 16
    assert win.views.sweep.n_cells == 6  # 2 amplitudes x 3 cylinders
    assert win.views.bands.n_bands >= 2
    assert win.run_panel.progress.value() == 6
    # the file is complete
    out = Path(win.run_panel.out_edit.text())  # the fixture's (runs/ for the docs' pictures)
    run = read_run(out)
    assert run.status == "complete"
    assert bool(np.all(run.scans["ltr"].done == PointState.DONE))
    assert np.all(np.isfinite(run.scans["ltr"].velocity))
    # the same logging as the command line: the run's log file beside the run file
    log = out.with_suffix(".log").read_text()
    assert "biafc.gui: starting run" in log and "biafc.run: run started" in log
    assert "complete: 6 points" in log
    # each line once: the window does not record again what the engine recorded (before:
    # "homing the stage" and "run complete" from biafc.run and again from biafc.gui)
    said = [line.split(": ", 1)[1] for line in log.splitlines() if ": " in line]
    assert sum(m.startswith("homing the stage") for m in said) == 1
    assert not {m for m in said if said.count(m) > 1}, log
    # the window kept turning
    assert longest < MAX_STALL_MS, f"event loop stalled {longest:.0f} ms"
    print(f"longest event-loop stall during the smoke run: {longest:.1f} ms")
    win.views.setCurrentIndex(2)
    qtbot.wait(50)
    assert win.grab().save(str(screenshots / "bench_window_finished.png"))
    assert shot_mid
    for index, name in ((1, "spectrum"), (3, "quasi_bands"), (4, "amplitude_sweep")):
        win.views.setCurrentIndex(index)
        qtbot.wait(50)
        assert win.views.grab().save(str(screenshots / f"view_{name}.png"))


def test_pause_resume_abort_buttons(qtbot: Any, tmp_path: Path) -> None:
    win = MainWindow(None, SMOKE, assembler=make_assembler(read_sleep_s=0.25))
    win.confirm_close = lambda: True  # type: ignore[method-assign]
    qtbot.addWidget(win)
    win.show()
    rp = win.run_panel
    rp.out_edit.setText(str(tmp_path / "a.h5"))
    connect(qtbot, win)
    assert not rp.pause_button.isEnabled()
    rp.start_button.click()
    wait_until(qtbot, lambda: win.live.n_points >= 1)
    assert rp.pause_button.isEnabled() and not rp.start_button.isEnabled()
    # the run's bench and protocol: Reconnect did nothing and the editor took edits, before
    assert not win.bench_panel.connect_button.isEnabled()
    assert win.protocol_panel.editor.isReadOnly()
    rp.pause_button.click()
    wait_until(qtbot, lambda: rp.resume_button.isEnabled())
    assert win.engine.state.value == "paused"
    qtbot.wait(800)  # the point in flight (2 reads of 0.25 s) completes
    win._on_events()
    assert win.run_panel.where_label.text().startswith("paused")  # it kept the last ETA
    n_paused = win.live.n_points
    qtbot.wait(500)
    assert win.live.n_points == n_paused, "points measured while paused"
    rp.resume_button.click()
    wait_until(qtbot, lambda: rp.pause_button.isEnabled())  # running again
    win._on_events()
    assert not win.run_panel.where_label.text().startswith("paused")  # it stayed "paused"
    assert win.engine.state.value == "running" and n_paused < 6
    with qtbot.waitSignal(win.run_finished, timeout=60_000) as blocker:
        rp.abort_button.click()
    assert blocker.args == ["aborted"]
    run = read_run(tmp_path / "a.h5")
    assert run.status == "aborted"
    assert 0 < _done_count(tmp_path / "a.h5") < 6
    # Start waits for the read of the instruments' state that follows a run (it worked on them)
    wait_until(qtbot, lambda: rp.start_button.isEnabled(), timeout_s=10)
    assert not rp.abort_button.isEnabled()
    assert win.bench_panel.connect_button.isEnabled()
    assert not win.protocol_panel.editor.isReadOnly()
    if hasattr(win.instruments.world, "outputs"):  # fake bench: generator outputs off
        assert not any(win.instruments.world.outputs.values())
    # resume the interrupted file from the window: it completes, and its views hold every
    # point (before, the maps left out those already in the file, and progress began at 0)
    n_before = _done_count(tmp_path / "a.h5")
    with qtbot.waitSignal(win.run_finished, timeout=60_000) as blocker:
        assert win.start_run(tmp_path / "a.h5")
        wait_until(qtbot, lambda: win.running)
        assert rp.progress.value() >= n_before
    assert blocker.args == ["complete"]
    assert _done_count(tmp_path / "a.h5") == 6
    assert win.live.n_points == 6
    win._redraw()
    assert win.views.sweep.n_cells == 6


def test_validation_error_shown_in_protocol_panel(qtbot: Any, window: MainWindow) -> None:
    pp = window.protocol_panel
    text = SMOKE.read_text()
    pp.editor.setPlainText(text.replace("f_center: 8.92 kHz", "f_center: 8.92"))
    qtbot.waitUntil(lambda: not pp.valid, timeout=2000)  # as you type (debounced)
    msg = pp.status_label.text()
    assert "smoke.yaml:5" in msg and "f_center" in msg and "unit" in msg, msg
    # the resolved fields go with the error: before, the last valid values stayed beside it
    assert pp.fields.topLevelItemCount() == 0
    assert not window.start_run()
    assert window.engine is None
    # Start and Dry run wait for a valid protocol (they were enabled, and only logged a refusal)
    assert not window.run_panel.start_button.isEnabled() and not pp.dry_button.isEnabled()
    assert window.run_panel.resume_file_button.isEnabled()  # a resume runs the file's protocol
    pp.editor.setPlainText(text.replace("cylinders: [1, 8, 16]", "cylinders: [1, 8, 99]"))
    qtbot.waitUntil(lambda: "99" in pp.status_label.text(), timeout=2000)
    assert not pp.valid
    pp.editor.setPlainText(text)
    qtbot.waitUntil(lambda: pp.valid, timeout=2000)
    assert "6 points" in pp.status_label.text()
    assert window.run_panel.start_button.isEnabled() and pp.dry_button.isEnabled()


def test_the_window_refuses_what_run_protocol_refuses_as_typed(
    qtbot: Any, window: MainWindow
) -> None:
    """Issue 16: the editor's text goes through daq.request.validate_request, the check of
    run_protocol: a record too short for the burst's transit, a bare '1 V' amplitude."""
    from daq.request import RequestError, validate_request
    from protocols.schema import parse_protocol

    pp = window.protocol_panel
    text = SMOKE.read_text()
    short = text.replace("duration: 10 ms", "duration: 2.5 ms")
    with pytest.raises(RequestError) as refused:
        validate_request(parse_protocol(short, "smoke.yaml"), window.bench_file)
    pp.editor.setPlainText(short)
    qtbot.waitUntil(lambda: not pp.valid, timeout=2000)
    assert pp.status_label.text() == f"✗ {refused.value}"
    assert "transit" in pp.status_label.text()
    pp.editor.setPlainText(text.replace("[0.5 um, 3 um]", "[1 V]"))
    qtbot.waitUntil(lambda: "Vpk" in pp.status_label.text(), timeout=2000)
    assert not pp.valid and not window.start_run() and window.engine is None


def test_dry_run_on_the_lab_bench_says_how_long_homing_may_take(
    qtbot: Any, window: MainWindow
) -> None:
    """The window's Dry run says the stage's homing bound, as run_protocol's does."""
    from protocols.bench import default_bench_path

    assert window.load_bench(default_bench_path().with_name("lab_bench.yaml"))
    qtbot.waitUntil(lambda: window.plan is not None, timeout=5000)
    window.dry_run()
    line = window.log_view.lines[-1]
    assert "dry run: 6 points" in line, line
    assert "homes if it is not homed: at most 20 s (X-LSM500A: 500 mm at 25 mm/s" in line, line


def test_the_safe_state_button_says_what_it_could_not_confirm(
    qtbot: Any, window: MainWindow
) -> None:
    """Outside a run the button takes the run's own path to the safe state: outputs off and
    read back, then the stage asked whether its axis came to rest. Before, it had a copy of
    that path without the stage, and said "instruments in safe state" beside a moving axis."""
    connect(qtbot, window)
    window.bench_panel.safe_button.click()
    qtbot.waitUntil(lambda: "instruments in safe state" in window.log_view.lines[-1], timeout=5000)
    stage = window.instruments.stage
    stage.is_moving = lambda: True  # type: ignore[method-assign]
    window.bench_panel.safe_button.click()
    qtbot.waitUntil(lambda: "safe state:" in window.log_view.lines[-1], timeout=5000)
    line = window.log_view.lines[-1]
    assert "SWITCH OFF BY HAND: stage controller: the axis still moves" in line, line
    assert window.bench_panel.safe_button.isEnabled()  # disabled only while it works


def test_a_disconnect_during_the_safe_state_closes_the_instruments_after_it(
    qtbot: Any, window: MainWindow
) -> None:
    """Reconnecting while the Safe state worked closed the same transports from another
    thread, whose replies could cross; now the close waits for the Safe state's end."""
    import threading

    connect(qtbot, window)
    inst = window.instruments
    release, closed = threading.Event(), []
    real_safe, real_close = inst.stage.safe_state, inst.close

    def slow_safe() -> None:
        release.wait(10)
        real_safe()

    def close() -> None:
        closed.append(release.is_set())
        real_close()

    inst.stage.safe_state = slow_safe
    inst.close = close
    window.bench_panel.safe_button.click()
    qtbot.wait(100)
    window._disconnect()
    qtbot.wait(200)
    assert closed == []  # not while the Safe state works on them
    release.set()  # the close waits on the instrument lock, the log line on the GUI thread
    qtbot.waitUntil(
        lambda: (
            closed == [True] and "before the bench was disconnected" in window.log_view.lines[-1]
        ),
        timeout=5000,
    )


def test_close_during_run_aborts_safely(qtbot: Any, tmp_path: Path) -> None:
    win = MainWindow(None, SMOKE, assembler=make_assembler(read_sleep_s=0.1))
    qtbot.addWidget(win)
    win.show()
    win.run_panel.out_edit.setText(str(tmp_path / "c.h5"))
    asked: list[bool] = []
    answers = iter([False, True])

    def confirm() -> bool:
        asked.append(True)
        return next(answers)

    win.confirm_close = confirm  # type: ignore[method-assign]
    connect(qtbot, win)
    win.run_panel.start_button.click()
    wait_until(qtbot, lambda: win.live.n_points >= 1)
    assert not win.close()  # answered "no": still open, still running
    assert win.running
    t0 = time.monotonic()
    assert win.close()  # answered "yes": aborts, waits for the safe state
    assert len(asked) == 2
    assert time.monotonic() - t0 < 30
    assert read_run(tmp_path / "c.h5").status == "aborted"
    assert win.exit_status == 1  # as run_protocol's for an aborted run (before: the window's 0)


def test_browse_finished_run_file(qtbot: Any, window: MainWindow, tmp_path: Path) -> None:
    win = window
    connect(qtbot, win)
    with qtbot.waitSignal(win.run_finished, timeout=120_000):
        win.run_panel.start_button.click()
    fresh = MainWindow(None, None, assembler=make_assembler())
    qtbot.addWidget(fresh)
    with qtbot.waitCallback(timeout=30_000) as cb:
        fresh.open_run_file(Path(win.run_panel.out_edit.text()), on_done=cb)
    assert cb.args == [True]
    assert fresh.live.n_points == 6
    assert fresh.views.spatial.n_rows == 3
    assert fresh.views.sweep.n_cells == 6
    # a run file with no point measured: the views empty, not the last file's (before)
    from daq.store import create_run
    from protocols.runfile import ScanSpec

    empty = tmp_path / "empty.h5"
    run = read_run(Path(win.run_panel.out_edit.text()))
    specs = [
        ScanSpec(s.direction, s.amplitudes, s.amplitude_units, s.cylinders, s.time_s,
                 s.f_center_Hz, s.cycles, s.width_s, s.averages, s.drive_units)
        for s in run.scans.values()
    ]  # fmt: skip
    create_run(
        empty, backend="sim", chain=run.chain, scans=specs, protocol_yaml="", bench_yaml="",
        snapshot={}, seed=0,
    ).close("aborted")  # fmt: skip
    with qtbot.waitCallback(timeout=30_000) as cb:
        fresh.open_run_file(empty, on_done=cb)
    assert cb.args == [True] and fresh.live.n_points == 0
    assert fresh.views.trace.c_vel.xData is None or len(fresh.views.trace.c_vel.xData) == 0
    assert fresh.views.spatial.image.image is None


@pytest.mark.parametrize("bad", ["missing.yaml"])
def test_missing_protocol_file_is_one_line(qtbot: Any, bad: str, tmp_path: Path) -> None:
    win = MainWindow(None, None, assembler=make_assembler())
    qtbot.addWidget(win)
    assert not win.load_protocol(tmp_path / bad)
    assert bad in win.protocol_panel.status_label.text()


def test_export_figures_from_window(qtbot: Any, window: MainWindow, tmp_path: Path) -> None:
    win = window
    connect(qtbot, win)
    with qtbot.waitSignal(win.run_finished, timeout=120_000):
        win.run_panel.start_button.click()
    with qtbot.waitCallback(timeout=120_000) as cb:
        win.export_figures(Path(win.run_panel.out_edit.text()), tmp_path / "figs", on_done=cb)
    assert cb.args == [True], win.log_view.lines[-2:]
    assert any((tmp_path / "figs").glob("*.png"))


def test_an_unsafe_end_is_shown_in_red_naming_the_output(qtbot: Any, tmp_path: Path) -> None:
    """Issue 15: the emulated generator stops answering mid-run; the window says ``unsafe`` and
    what to switch off by hand, as the CLI does, and not "complete"."""

    def silent(bf: Any, seed: int | None) -> Any:
        return connect_bench(
            bf, seed=seed, faults={"generator_silent": True, "after_acquisitions": 3}
        )

    win = MainWindow(None, SMOKE, assembler=silent)
    win.confirm_close = lambda: True  # type: ignore[method-assign]
    qtbot.addWidget(win)
    win.show()
    width = win.width()
    win.run_panel.out_edit.setText(str(tmp_path / "u.h5"))
    connect(qtbot, win)
    with qtbot.waitSignal(win.run_finished, timeout=60_000) as blocker:
        win.run_panel.start_button.click()
    assert blocker.args == ["unsafe"]
    text = win.run_panel.where_label.text()
    assert text.startswith("run UNSAFE") and "SWITCH OFF BY HAND" in text and "output 1" in text
    assert "b00000" in win.run_panel.where_label.styleSheet()
    assert "SWITCH OFF BY HAND" in win.statusBar().currentMessage()
    assert read_run(tmp_path / "u.h5").status == "unsafe"
    # the long line wraps: before, it widened the window (1500 to 3421 px) past the screen, and
    # its end and the Abort button went off it
    qtbot.wait(50)
    assert win.width() == width and win.minimumSizeHint().width() < width
    # the bench panel no longer says "connected" beside outputs listed off (the state last
    # asked for): it says UNSAFE, and the outputs' state as read, unknown
    assert "UNSAFE" in win.bench_panel.status_label.text()

    def output_rows() -> list[tuple[str, str]]:
        tree = win.bench_panel.tree
        rows = []
        for i in range(tree.topLevelItemCount()):
            top = tree.topLevelItem(i)
            rows += [(top.child(j).text(0), top.child(j).text(1)) for j in range(top.childCount())]
        return [r for r in rows if r[0].endswith("output_on")]

    wait_until(qtbot, lambda: ("channels.1.output_on", "None") in output_rows())
    assert ("channels.1.output_on", "False") not in output_rows()
    assert win.run_panel.abort_button.geometry().right() <= win.run_panel.width()


def test_a_resume_of_a_file_another_process_writes_is_refused(
    qtbot: Any, window: MainWindow, tmp_path: Path
) -> None:
    """Issue 15: the window refuses (nothing moves, the file is untouched) and names the other
    writer, as run_protocol does with exit status 2; once that process is gone it resumes."""
    import json
    import socket
    import subprocess
    import sys

    from daq.engine import RunEngine
    from daq.store.lock import lock_path
    from protocols.bench import load_bench
    from protocols.schema import load_protocol

    part = tmp_path / "part.h5"
    bf = load_bench()
    inst = connect_bench(bf, faults={"stage_stall": True, "after_acquisitions": 4})
    assert RunEngine(load_protocol(SMOKE), bf, inst, part).run().status == "failed"
    before = part.read_bytes()
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock_path(part).write_text(json.dumps({"host": socket.gethostname(), "pid": other.pid}))
        connect(qtbot, window)
        assert not window.start_run(part)  # refused before the engine is made (issue 16)
        assert window.engine is None
        text = window.run_panel.where_label.text()
        assert text.startswith("run refused") and f"process {other.pid}" in text
        assert part.read_bytes() == before
    finally:
        other.kill()
        other.wait()
    with qtbot.waitSignal(window.run_finished, timeout=60_000) as blocker:
        assert window.start_run(part)  # the lock of a dead process is stale: taken over
    assert blocker.args == ["complete"]


def test_a_closed_console_aborts_the_windows_run_before_windows_ends_it(
    qtbot: Any, tmp_path: Path
) -> None:
    """The window started from a Windows console that is then closed: Windows calls the
    console handler (daq.cli.console_close) on a thread of its own and ends the process when it
    returns. It now returns once the run is aborted and safe; before, no handler was held and
    the run was cut off where it stood."""
    import threading

    from .conftest import running_window

    win = running_window(qtbot, tmp_path / "w.h5")
    engine = win.engine
    returned: list[Any] = []

    def windows() -> None:
        win.console_closed("console window closed")
        returned.append(engine.result)  # what there was when Windows would end the process

    handler = threading.Thread(target=windows)
    handler.start()
    wait_until(qtbot, lambda: not handler.is_alive(), timeout_s=10)
    assert returned[0] is not None and returned[0].status == "aborted"
    assert returned[0].safe_state_s is not None  # the safe state confirmed before the end
    assert "interrupted: console window closed" in returned[0].reason
    run = read_run(tmp_path / "w.h5")
    assert run.status == "aborted" and 0 < _done_count(tmp_path / "w.h5") < 6


def test_the_window_holds_the_console_while_it_runs(qapp: Any, monkeypatch: Any) -> None:
    import daq.cli.console_close as console_close
    import daq.gui.main_window as main_window
    from daq.gui import app

    from .conftest import StubWindow, window_args

    held: list[Any] = []

    class Hold:
        def remove(self) -> None:
            held.append("removed")

    def hold(on_close: Any, kernel32: Any = None) -> Hold:
        held.append(on_close)
        return Hold()

    monkeypatch.setattr(main_window, "MainWindow", StubWindow)
    monkeypatch.setattr(console_close, "hold_console_close", hold)
    monkeypatch.setattr(type(qapp), "exec", lambda self: 0)
    monkeypatch.setattr("daq.logsetup.configure", lambda *a, **k: None)
    assert app.run_window(window_args()) == 0
    assert held[0].__func__ is StubWindow.console_closed and held[1] == "removed"


def test_a_file_that_is_no_run_file_is_named_once(qtbot: Any, tmp_path: Path) -> None:
    """Before: '…/bench.yaml: …/bench.yaml: not an HDF5 file'."""
    win = MainWindow(None, None, assembler=make_assembler())
    qtbot.addWidget(win)
    bad = tmp_path / "bench.yaml"
    bad.write_text("name: x\n")
    with qtbot.waitCallback(timeout=30_000) as cb:
        win.open_run_file(bad, on_done=cb)
    assert cb.args == [False]
    line = win.log_view.lines[-1]
    assert line.count(str(bad)) == 1, line


def test_start_waits_while_the_safe_state_works_on_the_instruments(
    qtbot: Any, window: MainWindow
) -> None:
    """Start stayed enabled while the Safe state worked: the run homed and moved the stage and
    fired bursts from a second thread while the Safe state's worker was still inside it (a
    second reader's trace). Start and Resume file now wait for it."""
    import threading

    connect(qtbot, window)
    inst = window.instruments
    release, moves = threading.Event(), []
    real_safe, real_move = inst.stage.safe_state, inst.stage.move_to

    def slow_safe() -> None:
        release.wait(10)
        real_safe()

    def move_to(*a: Any, **k: Any) -> Any:
        moves.append(release.is_set())
        return real_move(*a, **k)

    inst.stage.safe_state = slow_safe
    inst.stage.move_to = move_to
    window.bench_panel.safe_button.click()
    qtbot.wait(100)
    rp = window.run_panel
    assert not rp.start_button.isEnabled() and not rp.resume_file_button.isEnabled()
    assert window.start_run() is False  # from code: refused, said
    assert "cannot start yet: the Safe state is still working" in window.log_view.lines[-1]
    assert window.engine is None and moves == []
    release.set()
    qtbot.waitUntil(lambda: rp.start_button.isEnabled(), timeout=5000)
    with qtbot.waitSignal(window.run_finished, timeout=60_000):
        rp.start_button.click()
    assert moves and all(moves)  # every move after the Safe state ended


def test_abort_while_the_bench_connects_cancels_the_start(qtbot: Any, tmp_path: Path) -> None:
    """Abort while the run was 'starting' (the bench connecting) did nothing, and the run then
    went ahead to its end (a second reader)."""
    import threading

    gate = threading.Event()
    real = make_assembler()

    def slow(bf: Any, seed: int | None) -> Any:
        gate.wait(10)
        return real(bf, seed)

    win = MainWindow(None, SMOKE, assembler=slow)
    qtbot.addWidget(win)
    win.run_panel.out_edit.setText(str(tmp_path / "never.h5"))
    win.show()
    win.run_panel.start_button.click()
    assert win.run_panel.abort_button.isEnabled()
    win.run_panel.abort_button.click()
    assert (
        "start cancelled" in win.log_view.lines[-1]
        and "nothing was switched on" in (win.log_view.lines[-1])
    )
    with qtbot.waitSignal(win.connected, timeout=60_000):
        gate.set()
    qtbot.wait(300)
    assert win.engine is None and not (tmp_path / "never.h5").exists()
    assert win.run_panel.start_button.isEnabled()


def test_the_unsafe_mark_goes_once_the_safe_state_is_confirmed_and_the_status_is_kept(
    qtbot: Any, tmp_path: Path
) -> None:
    """The bench panel's 'UNSAFE' of a run stayed up after a Safe state had confirmed every
    output off (until Reconnect); and the window's process exited 0 after an unsafe run."""

    win = _run_with_faults(
        qtbot, {"generator_silent": True, "after_acquisitions": 3}, tmp_path / "u.h5"
    )
    assert win.bench_panel.status_label.text().startswith("✗ UNSAFE")
    assert win.exit_status == 3  # as run_protocol's
    win.instruments.world.faults.clear()  # the generator answers again
    qtbot.waitUntil(lambda: win.bench_panel.safe_button.isEnabled(), timeout=5000)
    win.bench_panel.safe_button.click()
    qtbot.waitUntil(lambda: "instruments in safe state" in win.log_view.lines[-1], timeout=10_000)
    assert not win.bench_panel.status_label.text().startswith("✗ UNSAFE")


def test_the_dry_run_checks_the_output_as_run_protocol_does(
    qtbot: Any, window: MainWindow, tmp_path: Path
) -> None:
    done = tmp_path / "done.h5"
    window.run_panel.out_edit.setText(str(done))
    connect(qtbot, window)
    with qtbot.waitSignal(window.run_finished, timeout=60_000):
        window.run_panel.start_button.click()
    window.dry_run()  # the same output again: a complete run, refused by the command line
    assert "dry run: refused" in window.log_view.lines[-1]
    assert "complete" in window.log_view.lines[-1]


def test_resume_file_continues_the_files_own_protocol(qtbot: Any, tmp_path: Path) -> None:
    """Resume file… checked and ran the editor's protocol: a run of another protocol was
    refused ('started with another protocol'), where run_protocol --resume, which takes the
    protocol and bench from the file, completed it (a second reader)."""
    from daq.cli import run_protocol as rp
    from protocols.bench import default_bench_path

    alt = tmp_path / "smoke_alt.yaml"
    alt.write_text(SMOKE.read_text().replace("name: smoke", "name: smoke_alt"))
    failing = tmp_path / "failing.yaml"
    failing.write_text(
        default_bench_path()
        .read_text()
        .replace("faults: {}", "faults: {stage_stall: true, after_acquisitions: 4}")
    )
    f = tmp_path / "alt.h5"
    assert rp.main([str(alt), "--bench", str(failing), "--out", str(f), "-q"]) == 1
    win = MainWindow(None, SMOKE, assembler=make_assembler())
    qtbot.addWidget(win)
    win.show()
    connect(qtbot, win)
    with qtbot.waitSignal(win.run_finished, timeout=60_000) as blocker:
        assert win.start_run(f), win.log_view.lines[-2:]
    assert blocker.args == ["complete"], win.log_view.lines[-3:]
    assert read_run(f).status == "complete"
    assert read_run(f).attrs["protocol_yaml"].startswith(alt.read_text()[:40])


def test_failed_points_are_marked_in_the_live_views(
    qtbot: Any, tmp_path: Path, screenshots: Path
) -> None:
    """Failed points were not handled by the window: the maps showed them as cells not
    measured yet, and the colour of a missing cell was the scale's lowest, that of a quiet
    measured one (a second reader: 4 of 6 points failed, none visible)."""

    nan_reads = {"digitiser_nan": True, "after_acquisitions": 4}
    win = _run_with_faults(qtbot, nan_reads, tmp_path / "f.h5")
    win._redraw()
    n_failed = int(np.sum(read_run(tmp_path / "f.h5").scans["ltr"].done == PointState.FAILED))
    assert n_failed >= 3 and win.live.n_failed == n_failed
    sweep = win.views.sweep
    assert sweep.n_failed == n_failed and len(sweep.failed_marks.data) == n_failed
    assert "failed: red x" in sweep.plotItem.titleLabel.text
    img = sweep.image.image
    assert int(np.isnan(img).sum()) == n_failed  # outside the colour scale, not its lowest
    win.views.setCurrentWidget(sweep)
    sweep.grab().save(str(screenshots / "window_failed_points.png"))
    assert "point(s) failed" in win.views.trace.p_vel.titleLabel.text
    win.open_run_file(tmp_path / "f.h5")
    qtbot.waitUntil(lambda: "opened f.h5" in win.log_view.lines[-1], timeout=10_000)
    assert f"{n_failed} failed" in win.log_view.lines[-1]


def test_the_first_compile_of_the_model_is_said_in_the_window(
    qtbot: Any, window: MainWindow
) -> None:
    """The first simulated run compiles the DEM kernel on the engine's thread (20-80 s): the
    window showed "homing the stage" all that time, where the command line says what happens.
    The kernel's reporter now reaches the window, from whichever thread compiles."""
    import threading

    from sim_backend.dem import kernel_cache

    reporter = kernel_cache._REPORTER
    assert reporter is not None

    def compile_elsewhere() -> None:
        reporter("start", 0.0, Path("/cache/numba"), True)
        reporter("tick", 3.0, Path("/cache/numba"), True)

    t = threading.Thread(target=compile_elsewhere)
    t.start()
    t.join()
    qtbot.waitUntil(lambda: "... 3 s" in window.run_panel.where_label.text(), timeout=5000)
    assert "compiling the DEM kernel (once per installation)" in (
        window.run_panel.where_label.text()
    )
    assert any("compiling the DEM kernel for this machine" in ln for ln in window.log_view.lines)
    reporter("done", 21.5, Path("/cache/numba"), True)
    assert window.log_view.lines[-1].endswith("DEM kernel ready after 21.5 s")


def test_what_the_second_reader_found_in_the_window_fixes(qtbot: Any, tmp_path: Path) -> None:
    """A failed connect with a start pending left the run panel 'starting' for ever; an empty
    editor left Start enabled; a window closed first left the model's compile reporter pointing
    at itself; a run where every point failed drew no cross."""
    from sim_backend.dem import kernel_cache

    def broken(bf: Any, seed: int | None) -> Any:
        raise OSError("no such device")

    empty = MainWindow(None, None, assembler=broken)
    qtbot.addWidget(empty)
    assert not empty.run_panel.start_button.isEnabled()  # nothing to start
    win = MainWindow(None, SMOKE, assembler=broken)
    qtbot.addWidget(win)
    win.run_panel.out_edit.setText(str(tmp_path / "x.h5"))
    with qtbot.waitSignal(win.connected, timeout=10_000):
        win.run_panel.start_button.click()
    assert win.run_panel.start_button.isEnabled() and not win.run_panel.abort_button.isEnabled()
    empty.close()  # opened first, closed first: the reporter stays the open window's
    assert kernel_cache._REPORTER is win._report
    win.close()

    bad = _run_with_faults(qtbot, {"digitiser_nan": True}, tmp_path / "all_failed.h5")
    bad._redraw()
    assert bad.live.n_failed == 6 and len(bad.views.sweep.failed_marks.data) == 6
    assert "6 failed" in bad.views.trace.p_vel.titleLabel.text


def test_closing_the_window_waits_for_a_safe_state_under_way(
    qtbot: Any, window: MainWindow
) -> None:
    """Closing closed the transports under a Safe state still working on them: it ended with
    'transport closed, cannot send OUTP1?' (a second reader). The close waits for it."""
    import threading

    connect(qtbot, window)
    inst = window.instruments
    order: list[str] = []
    real_safe, real_close = inst.stage.safe_state, inst.close

    def slow_safe() -> None:
        time.sleep(1.0)
        order.append("safe state done")
        real_safe()

    def close() -> None:
        order.append("closed")
        real_close()

    inst.stage.safe_state = slow_safe
    inst.close = close
    window.bench_panel.safe_button.click()
    qtbot.wait(100)
    assert threading.active_count() > 1
    window.close()
    assert order[:2] == ["safe state done", "closed"], order  # (closing runs its own after)


def _run_with_faults(qtbot: Any, faults: dict[str, Any], out: Path) -> MainWindow:
    """A window on the simulated bench with ``faults``, its smoke run into ``out`` ended."""

    def faulty(bf: Any, seed: int | None) -> Any:
        return connect_bench(bf, seed=seed, faults=faults)

    win = MainWindow(None, SMOKE, assembler=faulty)
    qtbot.addWidget(win)
    win.show()
    win.run_panel.out_edit.setText(str(out))
    connect(qtbot, win)
    with qtbot.waitSignal(win.run_finished, timeout=60_000):
        win.run_panel.start_button.click()
    return win


def test_a_stop_signal_keeps_an_unsafe_status_and_gives_its_own_otherwise(
    qtbot: Any, tmp_path: Path
) -> None:
    import signal

    for before, after in ((3, 3), (4, 128 + signal.SIGTERM)):
        win = MainWindow(None, SMOKE, assembler=make_assembler())
        qtbot.addWidget(win)
        win.exit_status = before  # the last run's (3 unsafe, 4 points failed)
        win.stop_signal(signal.SIGTERM)
        assert win.exit_status == after, (before, win.exit_status)


def test_a_bench_connected_after_the_bench_file_changed_is_closed(
    qtbot: Any, window: MainWindow
) -> None:
    """A second reader: the window dropped such a bench without closing it, and kept its ports
    and instrument locks until it closed (a run_protocol was refused "in use by" it)."""

    import threading

    go = threading.Event()

    class Dropped:
        closed = False

        def close(self) -> None:
            go.wait(5)
            Dropped.closed = True

    stale = object()  # a bench file that is no longer the window's
    window._connected(stale, (Dropped(), {}), None)
    # no new Connect to the same ports while it closes (a reviewer: the two overlapped)
    assert window._busy_connect and not Dropped.closed
    go.set()
    qtbot.waitUntil(lambda: Dropped.closed, timeout=5_000)
    qtbot.waitUntil(lambda: not window._busy_connect, timeout=5_000)
    assert window.instruments is None
