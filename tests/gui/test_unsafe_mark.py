"""The bench panel's UNSAFE of a run is taken down only by a confirmed safe state: not by a
Reconnect whose generator reports an output on, nor by a failed connect."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from daq.connect import connect_bench
from daq.gui.main_window import MainWindow

from .conftest import SMOKE, SlowDigitiser, connect, wait_until


def test_reconnect_keeps_unsafe_until_every_output_reads_back_off(
    qtbot: Any, tmp_path: Path
) -> None:
    calls: list[int] = []

    def bench(bf: Any, seed: int | None) -> Any:
        calls.append(1)
        if len(calls) == 1:  # the generator goes silent mid-run: the run ends UNSAFE
            return connect_bench(
                bf, seed=seed, faults={"generator_silent": True, "after_acquisitions": 3}
            )
        if len(calls) == 2:
            raise RuntimeError("VISA: no such resource")
        inst = connect_bench(bf, seed=seed)
        if len(calls) == 3:  # the output the run could not switch off is still on
            inst.world._inst.generator.channels[1].output_on = True
        return inst

    win = MainWindow(None, SMOKE, assembler=bench)
    win.confirm_close = lambda: True  # type: ignore[method-assign]
    qtbot.addWidget(win)
    win.show()
    win.run_panel.out_edit.setText(str(tmp_path / "u.h5"))
    connect(qtbot, win)
    with qtbot.waitSignal(win.run_finished, timeout=60_000) as blocker:
        win.run_panel.start_button.click()
    assert blocker.args == ["unsafe"]
    label = win.bench_panel.status_label
    assert label.text().startswith("✗ UNSAFE")
    qtbot.waitUntil(lambda: win.bench_panel.connect_button.isEnabled(), timeout=10_000)

    with qtbot.waitSignal(win.connected, timeout=60_000) as failed:  # a failed connect
        win.bench_panel.connect_button.click()
        assert label.text().startswith("✗ UNSAFE")  # while it connects too
    assert failed.args == [False]
    assert label.text().startswith("✗ UNSAFE") and "connect failed" in label.text()

    connect(qtbot, win)  # output 1 reads back ON
    assert label.text().startswith("✗ UNSAFE") and "b00000" in label.styleSheet()
    assert "output 1 is ON" in win.log_view.lines[-2]

    connect(qtbot, win)  # every output reads back off, the stage at rest
    assert not label.text().startswith("✗ UNSAFE")
    assert "connected" in label.text() and "b00000" not in label.styleSheet()
    assert win.exit_status == 3  # the run's, whatever the panel says now


def test_a_new_run_keeps_unsafe_until_its_end_confirms_the_safe_state(
    qtbot: Any, tmp_path: Path
) -> None:
    """Start took the last run's UNSAFE down before anything was read back: the panel said
    "connected" while the output the run could not switch off had not been confirmed off."""

    def bench(bf: Any, seed: int | None) -> Any:  # the generator goes silent mid-run
        inst = connect_bench(
            bf, seed=seed, faults={"generator_silent": True, "after_acquisitions": 3}
        )
        inst.digitiser = SlowDigitiser(inst.digitiser, 0.05)
        return inst

    win = MainWindow(None, SMOKE, assembler=bench)
    win.confirm_close = lambda: True  # type: ignore[method-assign]
    qtbot.addWidget(win)
    win.show()
    win.run_panel.out_edit.setText(str(tmp_path / "u.h5"))
    connect(qtbot, win)
    with qtbot.waitSignal(win.run_finished, timeout=60_000) as blocker:
        win.run_panel.start_button.click()
    assert blocker.args == ["unsafe"]
    label = win.bench_panel.status_label
    # what to switch off is named on the panel itself: the next run replaces the run's line
    assert label.text().startswith("✗ UNSAFE") and "u.h5" in label.text()
    assert "SWITCH OFF BY HAND" in label.text() and "output 1" in label.text()

    win.instruments.world.faults.clear()  # the generator answers again
    qtbot.waitUntil(lambda: win.run_panel.start_button.isEnabled(), timeout=10_000)
    win.run_panel.out_edit.setText(str(tmp_path / "next.h5"))
    with qtbot.waitSignal(win.run_finished, timeout=60_000) as blocker:
        win.run_panel.start_button.click()
        assert win.running and label.text().startswith("✗ UNSAFE")  # nothing confirmed yet
        wait_until(qtbot, lambda: win.live.n_points >= 1, 30)
        assert label.text().startswith("✗ UNSAFE")  # mid-run: still nothing read back
    assert blocker.args == ["complete"]
    assert not label.text().startswith("✗ UNSAFE") and "b00000" not in label.styleSheet()
    assert any("UNSAFE is taken down" in line for line in win.log_view.lines[-4:])
    assert win.exit_status == 0  # the last run's


def test_a_new_run_that_ends_unsafe_again_keeps_the_mark_naming_its_file(
    qtbot: Any, tmp_path: Path
) -> None:
    def bench(bf: Any, seed: int | None) -> Any:
        return connect_bench(
            bf, seed=seed, faults={"generator_silent": True, "after_acquisitions": 3}
        )

    win = MainWindow(None, SMOKE, assembler=bench)
    win.confirm_close = lambda: True  # type: ignore[method-assign]
    qtbot.addWidget(win)
    win.show()
    win.run_panel.out_edit.setText(str(tmp_path / "u.h5"))
    connect(qtbot, win)
    with qtbot.waitSignal(win.run_finished, timeout=60_000):
        win.run_panel.start_button.click()
    qtbot.waitUntil(lambda: win.run_panel.start_button.isEnabled(), timeout=10_000)
    label = win.bench_panel.status_label
    assert label.text().startswith("✗ UNSAFE")
    win.run_panel.out_edit.setText(str(tmp_path / "again.h5"))  # the generator still silent
    with qtbot.waitSignal(win.run_finished, timeout=60_000) as blocker:
        win.run_panel.start_button.click()
        assert label.text().startswith("✗ UNSAFE")
    assert blocker.args == ["unsafe"]
    assert label.text().startswith("✗ UNSAFE") and "again.h5" in label.text()
    assert not any("taken down" in line for line in win.log_view.lines)


def test_another_benchs_read_back_does_not_take_unsafe_down(qtbot: Any, tmp_path: Path) -> None:
    """A reviewer: after an UNSAFE end, opening another bench file and connecting read back
    that bench's outputs and took down the first bench's UNSAFE."""
    from protocols.bench import load_bench

    calls: list[int] = []

    def bench(bf: Any, seed: int | None) -> Any:
        calls.append(1)
        if len(calls) == 1:  # the generator goes silent mid-run: the run ends UNSAFE
            return connect_bench(
                bf, seed=seed, faults={"generator_silent": True, "after_acquisitions": 3}
            )
        return connect_bench(bf, seed=seed)

    win = MainWindow(None, SMOKE, assembler=bench)
    win.confirm_close = lambda: True  # type: ignore[method-assign]
    qtbot.addWidget(win)
    win.show()
    win.run_panel.out_edit.setText(str(tmp_path / "u.h5"))
    connect(qtbot, win)
    first = win.bench_file
    with qtbot.waitSignal(win.run_finished, timeout=60_000) as blocker:
        win.run_panel.start_button.click()
    assert blocker.args == ["unsafe"]
    label = win.bench_panel.status_label
    qtbot.waitUntil(lambda: win.bench_panel.connect_button.isEnabled(), timeout=10_000)
    other = tmp_path / "other_bench.yaml"
    other.write_text(load_bench().text.replace("name: simulated bench", "name: bench two", 1))
    assert win.load_bench(other)
    connect(qtbot, win)  # another bench's outputs read back off
    assert label.text().startswith("✗ UNSAFE")
    assert any("another bench than the one the UNSAFE run ran on" in line
               for line in win.log_view.lines[-4:])  # fmt: skip
    assert first is not None and win.load_bench(first.path)  # the UNSAFE run's own bench
    connect(qtbot, win)  # its outputs read back off: now it goes
    assert not label.text().startswith("✗ UNSAFE")
