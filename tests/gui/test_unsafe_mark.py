"""The bench panel's UNSAFE of a run is taken down only by a confirmed safe state: not by a
Reconnect whose generator reports an output on, nor by a failed connect."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from daq.connect import connect_bench
from daq.gui.main_window import MainWindow

from .conftest import SMOKE, connect


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
