"""A run is active from Start until the window has handled its end: the gap after Start (the
engine's thread not yet begun) and an end not yet handled (the GUI thread busy)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest

import daq.engine.engine as engine_module
from daq.connect import connect_bench
from daq.gui.main_window import MainWindow

from .conftest import SMOKE, connect, make_assembler, wait_until


@pytest.fixture
def slow_thread_start(monkeypatch: Any) -> None:
    """The engine's thread begins 0.3 s after Start (a loaded two-core PC)."""
    real = engine_module.RunEngine.run

    def run(self: Any) -> Any:
        time.sleep(0.3)
        return real(self)

    monkeypatch.setattr(engine_module.RunEngine, "run", run)


def _window(qtbot: Any, out: Path, assembler: Any = None) -> MainWindow:
    win = MainWindow(None, SMOKE, assembler=assembler or make_assembler(read_sleep_s=0.05))
    win.confirm_close = lambda: True  # type: ignore[method-assign]
    qtbot.addWidget(win)
    win.run_panel.out_edit.setText(str(out))
    win.show()
    return win


@pytest.mark.usefixtures("slow_thread_start")
def test_abort_in_the_gap_after_start_is_honoured(qtbot: Any, tmp_path: Path) -> None:
    """Abort pressed before the engine's thread began was ignored: the run went to its end."""
    win = _window(qtbot, tmp_path / "gap.h5")
    connect(qtbot, win)
    with qtbot.waitSignal(win.run_finished, timeout=60_000) as blocker:
        win.run_panel.start_button.click()
        assert win.running and win.run_panel.abort_button.isEnabled()
        win.run_panel.abort_button.click()
    assert blocker.args == ["aborted"]
    assert win.live.n_points == 0 and not win.running


@pytest.mark.usefixtures("slow_thread_start")
def test_pause_in_the_gap_after_start_pauses_the_run(qtbot: Any, tmp_path: Path) -> None:
    """Pause pressed before the engine's thread began was dropped: the run did not pause."""
    win = _window(qtbot, tmp_path / "gap.h5")
    connect(qtbot, win)
    win.run_panel.start_button.click()
    win.run_panel.pause_button.click()
    wait_until(qtbot, lambda: win.engine.state.value == "paused", 10)
    qtbot.wait(500)
    assert win.live.n_points == 0  # nothing measured while paused
    assert win.run_panel.resume_button.isEnabled()
    win.run_panel.resume_button.click()
    wait_until(qtbot, lambda: win.live.n_points >= 1, 30)
    with qtbot.waitSignal(win.run_finished, timeout=60_000) as blocker:
        win.run_panel.abort_button.click()
    assert blocker.args == ["aborted"]


@pytest.mark.usefixtures("slow_thread_start")
def test_close_in_the_gap_after_start_asks_and_aborts(qtbot: Any, tmp_path: Path) -> None:
    """Close in the gap did not ask, closed the transports under the starting engine (which
    then ended UNSAFE) and exited 0."""
    win = _window(qtbot, tmp_path / "gap.h5")
    asked: list[int] = []

    def confirm() -> bool:
        asked.append(1)
        return True

    win.confirm_close = confirm  # type: ignore[method-assign]
    connect(qtbot, win)
    win.run_panel.start_button.click()
    engine = win.engine
    assert win.close()
    assert asked == [1]
    assert engine.result is not None and engine.result.status == "aborted"
    assert win.exit_status == 1  # run_protocol's for an aborted run


def test_close_after_an_unsafe_end_not_yet_handled_exits_3(qtbot: Any, tmp_path: Path) -> None:
    """The engine ended UNSAFE while the GUI thread was busy: Close skipped the question (the
    engine's state was no longer 'running') and the window exited 0."""

    def silent(bf: Any, seed: int | None) -> Any:
        return connect_bench(
            bf, seed=seed, faults={"generator_silent": True, "after_acquisitions": 3}
        )

    win = _window(qtbot, tmp_path / "u.h5", assembler=silent)
    connect(qtbot, win)
    win.run_panel.start_button.click()
    deadline = time.monotonic() + 60
    while win.engine.result is None and time.monotonic() < deadline:
        time.sleep(0.01)  # the GUI thread busy: no event handled
    assert win.engine.result is not None and win.engine.result.status == "unsafe"
    assert win.running  # its end is not handled yet
    assert win.close()
    assert win.exit_status == 3
    assert win.bench_panel.status_label.text().startswith("✗ UNSAFE")


def test_instruments_connected_after_the_window_closed_are_closed(
    qtbot: Any, tmp_path: Path
) -> None:
    """Close while Start waited for the bench to connect: the instruments that arrived after
    were kept on the closed window, their ports and instrument locks open."""
    import threading

    gate = threading.Event()
    made: list[Any] = []
    real = make_assembler()

    def slow(bf: Any, seed: int | None) -> Any:
        gate.wait(10)
        inst = real(bf, seed)
        closed = inst.close
        inst.closed = False

        def close() -> None:
            inst.closed = True
            closed()

        inst.close = close
        made.append(inst)
        return inst

    win = _window(qtbot, tmp_path / "never.h5", assembler=slow)
    win.run_panel.start_button.click()  # not connected: it connects first
    assert win.run_panel.abort_button.isEnabled()
    threading.Timer(0.5, gate.set).start()
    assert win.close()
    qtbot.wait(500)  # the event loop of a process that goes on
    assert made and all(inst.closed for inst in made)
    assert win.instruments is None and win.engine is None
    assert not (tmp_path / "never.h5").exists()


def _action(win: MainWindow, text: str) -> Any:
    menu: Any = win.menuBar().actions()[0].menu()
    for action in menu.actions():
        if action.text() == text:
            return action
    raise KeyError(text)


def test_the_file_menus_open_waits_for_the_run_as_the_panels_buttons(
    qtbot: Any, tmp_path: Path, monkeypatch: Any
) -> None:
    """File → Open protocol… replaced the editor's protocol mid-run (the panel's Open… was
    locked, the menu's was not), and Open bench… worked while Start waited to connect."""
    from PySide6.QtWidgets import QFileDialog

    other = SMOKE.parent / "rtl_highamp.yaml"
    monkeypatch.setattr(
        QFileDialog, "getOpenFileName", staticmethod(lambda *a, **k: (str(other), ""))
    )
    win = _window(qtbot, tmp_path / "run.h5")
    opens = [_action(win, "Open protocol…"), _action(win, "Open bench…")]
    assert all(a.isEnabled() for a in opens)
    with qtbot.waitSignal(win.connected, timeout=60_000):
        win.run_panel.start_button.click()  # not connected: it connects first
        assert not any(a.isEnabled() for a in opens)  # starting
    wait_until(qtbot, lambda: win.live.n_points >= 1)
    assert not any(a.isEnabled() for a in opens)  # running
    opens[0].trigger()
    qtbot.wait(100)
    assert "smoke" in win.protocol_panel.path_edit.text()
    with qtbot.waitSignal(win.run_finished, timeout=60_000):
        win.run_panel.abort_button.click()
    assert all(a.isEnabled() for a in opens)


def test_a_run_file_opened_during_a_run_is_shown_after_it(qtbot: Any, tmp_path: Path) -> None:
    """File → Open run file… during a run logged "the file is shown after it ends", and it
    never was."""
    first = tmp_path / "first.h5"
    win = _window(qtbot, first)
    connect(qtbot, win)
    with qtbot.waitSignal(win.run_finished, timeout=60_000):
        win.run_panel.start_button.click()
    wait_until(qtbot, lambda: win.run_panel.start_button.isEnabled(), 10)
    win.run_panel.out_edit.setText(str(tmp_path / "second.h5"))
    win.run_panel.start_button.click()
    assert win.running
    shown: list[bool] = []
    with qtbot.waitSignal(win.run_finished, timeout=60_000):
        win.open_run_file(first, on_done=shown.append)
        wait_until(qtbot, lambda: any("shown after it ends" in x for x in win.log_view.lines), 30)
        assert win.running and not shown
    wait_until(qtbot, lambda: bool(shown), 30)
    assert shown == [True] and win.run_path == first
    assert any(f"opened {first.name}" in line for line in win.log_view.lines[-3:])


def test_a_bad_bench_file_is_said_and_nothing_starts_on_it(qtbot: Any, tmp_path: Path) -> None:
    """`biafc gui --bench BAD.yaml`: the protocol panel said valid and Start was enabled, Start
    then refused "the protocol is not valid", and Connect did nothing, silently."""
    from protocols.bench import default_bench_path

    text = default_bench_path().read_text(encoding="utf-8")
    assert "max_amplitude: 10 Vpp" in text
    bad = tmp_path / "bad_bench.yaml"
    bad.write_text(text.replace("max_amplitude: 10 Vpp", "max_amplitude: 10 V"), "utf-8")
    win = MainWindow(bad, SMOKE, assembler=make_assembler())
    win.confirm_close = lambda: True  # type: ignore[method-assign]
    qtbot.addWidget(win)
    win.run_panel.out_edit.setText(str(tmp_path / "never.h5"))
    win.show()
    error = "generator.max_amplitude: '10 V' does not say peak or peak-to-peak"
    assert error in win.bench_panel.status_label.text()
    status = win.protocol_panel.status_label.text()
    assert status.startswith("✗") and error in status and "valid" not in status.split(":")[0]
    assert not win.run_panel.start_button.isEnabled()
    assert not win.protocol_panel.dry_button.isEnabled()
    assert not win.bench_panel.connect_button.isEnabled()
    n = len(win.log_view.lines)
    win.connect_bench()  # from code: refused, naming the bench file's error
    assert error in win.log_view.lines[-1] and "cannot connect" in win.log_view.lines[-1]
    assert not win.start_run(tmp_path / "never.h5")  # Resume file…: the same
    assert error in win.log_view.lines[-1] and "cannot start" in win.log_view.lines[-1]
    assert len(win.log_view.lines) == n + 2 and win.instruments is None
    assert not (tmp_path / "never.h5").exists()


def test_a_run_names_its_file_in_the_title_and_dry_run_waits_for_it(
    qtbot: Any, tmp_path: Path
) -> None:
    """The title kept naming a file browsed before a run, during and after it; Dry run stayed
    enabled during a run and refused naming the window's own PID as the other writer."""
    browsed = tmp_path / "browsed.h5"
    win = _window(qtbot, browsed, assembler=make_assembler(read_sleep_s=0.0))
    connect(qtbot, win)
    with qtbot.waitSignal(win.run_finished, timeout=60_000):
        win.run_panel.start_button.click()
    with qtbot.waitCallback(timeout=30_000) as opened:
        win.open_run_file(browsed, on_done=opened)
    assert "browsed.h5" in win.windowTitle()
    wait_until(qtbot, lambda: win.run_panel.start_button.isEnabled(), 10)
    win.run_panel.out_edit.setText(str(tmp_path / "next.h5"))
    assert win.protocol_panel.dry_button.isEnabled()
    with qtbot.waitSignal(win.run_finished, timeout=60_000):
        win.run_panel.start_button.click()
        assert "next.h5" in win.windowTitle() and "browsed" not in win.windowTitle()
        assert not win.protocol_panel.dry_button.isEnabled()
        win.dry_run()  # from code: refused, without a PID
        assert "a run is active" in win.log_view.lines[-1]
    assert "next.h5" in win.windowTitle()
    assert win.protocol_panel.dry_button.isEnabled()


def test_a_bad_bench_file_opened_over_a_good_one_is_refused_and_the_old_one_said(
    qtbot: Any, tmp_path: Path
) -> None:
    """Open bench… of a bad file while a good one was loaded: the old bench stayed in use and
    the panel kept its path, but the status line showed only the new file's error, as if the
    bad file were the bench."""
    from protocols.bench import default_bench_path

    text = default_bench_path().read_text(encoding="utf-8")
    bad = tmp_path / "bad_bench.yaml"
    bad.write_text(text.replace("max_amplitude: 10 Vpp", "max_amplitude: 10 V"), "utf-8")
    win = _window(qtbot, tmp_path / "run.h5", assembler=make_assembler())
    connect(qtbot, win)
    good, path_shown = win.bench_file, win.bench_panel.path_edit.text()
    assert not win.load_bench(bad)
    error = "generator.max_amplitude: '10 V' does not say peak or peak-to-peak"
    status = win.bench_panel.status_label.text()
    assert status.startswith("✗ bench file refused:") and "bad_bench.yaml" in status
    assert error in status and "still using 'simulated bench'" in status
    assert path_shown in status and "connected (sim)" in status
    assert win.bench_panel.path_edit.text() == path_shown  # the bench in use, as before
    assert win.bench_file is good and win.instruments is not None
    assert win.log_view.lines[-1].split(" ", 2)[2].strip().startswith("bench file refused")
    assert error in win.log_view.lines[-1] and "still using" in win.log_view.lines[-1]
    assert win.run_panel.start_button.isEnabled()  # the old bench still runs
    assert win.bench_panel.connect_button.isEnabled()
    with qtbot.waitSignal(win.run_finished, timeout=60_000) as blocker:
        win.run_panel.start_button.click()
    assert blocker.args == ["complete"]


def test_resume_file_waits_for_a_bench_file_that_loads(
    qtbot: Any, tmp_path: Path, monkeypatch: Any
) -> None:
    """With a bad bench file, Resume file… stayed enabled: it opened the file dialog, and only
    after a file was chosen refused, naming the bench file's error."""
    from PySide6.QtWidgets import QFileDialog

    from protocols.bench import default_bench_path

    asked: list[int] = []

    def dialog(*args: Any, **kwargs: Any) -> tuple[str, str]:
        asked.append(1)
        return "", ""  # cancelled

    monkeypatch.setattr(QFileDialog, "getOpenFileName", staticmethod(dialog))
    text = default_bench_path().read_text(encoding="utf-8")
    bad = tmp_path / "bad_bench.yaml"
    bad.write_text(text.replace("max_amplitude: 10 Vpp", "max_amplitude: 10 V"), "utf-8")
    win = MainWindow(bad, SMOKE, assembler=make_assembler())
    win.confirm_close = lambda: True  # type: ignore[method-assign]
    qtbot.addWidget(win)
    win.show()
    error = "generator.max_amplitude: '10 V' does not say peak or peak-to-peak"
    assert not win.run_panel.resume_file_button.isEnabled()
    win.run_panel.set_state("idle")  # a run's end (or a refusal) sets the buttons again
    assert not win.run_panel.resume_file_button.isEnabled()
    win._ask_resume_file()  # from code: refused before the dialog, naming the bench's error
    assert asked == []
    assert "cannot resume" in win.log_view.lines[-1] and error in win.log_view.lines[-1]
    assert win.load_bench(None)  # a good one: Resume file… is back
    assert win.run_panel.resume_file_button.isEnabled()
    win._ask_resume_file()
    assert asked == [1]


def test_close_after_an_unhandled_end_does_not_start_reading_a_queued_file(
    qtbot: Any, tmp_path: Path
) -> None:
    """A reviewer: Close handled the ended run first, whose end then opened the run file
    queued during the run: a background read the closing window waited on."""
    win = MainWindow(None, SMOKE, assembler=make_assembler(read_sleep_s=0.05))
    win.confirm_close = lambda: True  # type: ignore[method-assign]
    qtbot.addWidget(win)
    win.show()
    win.run_panel.out_edit.setText(str(tmp_path / "a.h5"))
    connect(qtbot, win)
    with qtbot.waitSignal(win.run_finished, timeout=60_000):
        win.run_panel.start_button.click()
    first = tmp_path / "a.h5"
    win.run_panel.out_edit.setText(str(tmp_path / "b.h5"))
    qtbot.waitUntil(
        lambda: win.run_panel.start_button.isEnabled() and not win._busy, timeout=20_000
    )
    win.run_panel.start_button.click()
    assert win.running
    win.open_run_file(first)
    qtbot.waitUntil(lambda: win._open_after_run is not None, timeout=20_000)
    assert win.engine is not None
    win.engine.wait(60)  # the run ends; its FINISHED not handled yet (the GUI thread is here)
    opened: list[Path] = []
    real = win.open_run_file
    win.open_run_file = lambda p, cb=None: (opened.append(p), real(p, cb))  # type: ignore[method-assign]
    win.close()
    assert opened == []
