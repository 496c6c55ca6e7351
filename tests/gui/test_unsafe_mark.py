"""The bench panel's UNSAFE of a run is taken down only by a confirmed safe state: not by a
Reconnect whose generator reports an output on, nor by a failed connect."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from .conftest import connect, silent_generator, unsafe_window, wait_until


def test_reconnect_keeps_unsafe_until_every_output_reads_back_off(
    qtbot: Any, tmp_path: Path
) -> None:
    calls: list[int] = []
    unsafe_first = silent_generator(runs=1)  # the run ends UNSAFE

    def bench(bf: Any, seed: int | None) -> Any:
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("VISA: no such resource")
        inst = unsafe_first(bf, seed)
        if len(calls) == 3:  # the output the run could not switch off is still on
            inst.world._inst.generator.channels[1].output_on = True
        return inst

    win = unsafe_window(qtbot, tmp_path / "u.h5", bench)
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
    qtbot: Any, tmp_path: Path, screenshots: Path
) -> None:
    """Start took the last run's UNSAFE down before anything was read back: the panel said
    "connected" while the output the run could not switch off had not been confirmed off."""

    # the generator goes silent mid-run (its file named as no machine in the docs' picture)
    out = tmp_path / "u.h5" if not os.environ.get("BIAFC_SCREENSHOTS") else Path("runs/u.h5")
    for old in (out, out.with_suffix(".log"), out.with_name(out.name + ".lock")):
        old.unlink(missing_ok=True)
    win = unsafe_window(qtbot, out, silent_generator(read_sleep_s=0.05))
    label = win.bench_panel.status_label
    qtbot.wait(200)  # laid out for the mark's lines before the picture is taken
    picture = win.grab()
    # what to switch off is named on the panel itself: the next run replaces the run's line
    assert label.text().startswith("✗ UNSAFE") and "u.h5" in label.text()
    assert "SWITCH OFF BY HAND" in label.text() and "output 1" in label.text()
    assert picture.save(str(screenshots / "bench_window_unsafe.png"))  # docs/gui.md

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
    win = unsafe_window(qtbot, tmp_path / "u.h5", silent_generator())
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


def test_unsafe_goes_only_with_a_read_back_of_the_same_instruments(
    qtbot: Any, tmp_path: Path
) -> None:
    """A reviewer: after an UNSAFE end, another bench file's read-back took the mark down; and
    a fix that tied the mark to the bench file's text kept it up after the same bench file
    had only a comment added. The mark belongs to the instruments: the simulated bench, or a
    lab bench's generator and stage by their addresses."""
    from daq.gui.main_window import _bench_identity
    from protocols.bench import load_bench, parse_bench

    win = unsafe_window(qtbot, tmp_path / "u.h5", silent_generator(runs=1))
    label = win.bench_panel.status_label
    assert win._unsafe_bench == ("simulated",)
    qtbot.waitUntil(lambda: win.bench_panel.connect_button.isEnabled(), timeout=10_000)
    edited = tmp_path / "same_bench.yaml"  # the same bench file, a comment added
    edited.write_text("# checked the amplifier\n" + load_bench().text)
    assert win.load_bench(edited)
    connect(qtbot, win)  # the same (simulated) instruments read back off: the mark goes
    assert not label.text().startswith("✗ UNSAFE")

    # a lab bench: its generator and stage by address
    lab = Path(__file__).resolve().parents[2] / "protocols" / "benches" / "lab_bench.yaml"
    a = parse_bench(lab.read_text(), str(lab))
    commented = parse_bench("# a comment\n" + lab.read_text(), str(lab))
    other = parse_bench(
        lab.read_text().replace("TCPIP0::192.168.1.10::INSTR", "TCPIP0::192.168.1.11::INSTR"),
        str(lab),
    )
    assert _bench_identity(a) == _bench_identity(commented) != _bench_identity(other)
    kept_block = parse_bench(lab.read_text() + "simulation: {seed: 3}\n", str(lab))
    assert not kept_block.bench.simulated  # a lab bench that kept a simulation block
    assert _bench_identity(kept_block) == _bench_identity(a) != ("simulated",)
    win._unsafe_mark, win._unsafe_bench = "✗ UNSAFE: test", _bench_identity(a)
    win.bench_file = other
    win._clear_unsafe_mark("taken down")
    assert win._unsafe_mark is not None
    assert "other instruments than the UNSAFE run's" in win.log_view.lines[-1]
    win.bench_file = commented
    win._clear_unsafe_mark("taken down")
    assert win._unsafe_mark is None


LAB = Path(__file__).resolve().parents[2] / "protocols" / "benches" / "lab_bench.yaml"


def _lab_text(generator: str, stage: str) -> str:
    """The lab bench template with the generator and the stage at these addresses (written
    quoted: a YAML plain scalar would lose the spaces around them)."""
    text = LAB.read_text().replace("TCPIP0::192.168.1.10::INSTR", f'"{generator}"')
    return text.replace("ASRL4::INSTR ", f'"{stage}"', 1)


def _lab_bench(path: Path, generator: str, stage: str) -> Path:
    """:func:`_lab_text` written to ``path``."""
    path.write_text(_lab_text(generator, stage))
    return path


def _unsafe_lab_window(qtbot: Any, tmp_path: Path, generator: str, stage: str) -> Any:
    """The window on a lab bench file naming ``generator`` and ``stage`` (the instruments
    themselves simulated: the bench file only names them), after a run that ended UNSAFE;
    then the outputs read back off at each connect."""
    from daq.gui.main_window import MainWindow
    from protocols.bench import load_bench

    from .conftest import SMOKE

    simulated, unsafe_first = load_bench(None), silent_generator(runs=1)
    bench = _lab_bench(tmp_path / "lab.yaml", generator, stage)
    win = MainWindow(bench, SMOKE, assembler=lambda bf, seed: unsafe_first(simulated, seed))
    win.confirm_close = lambda: True  # type: ignore[method-assign]
    qtbot.addWidget(win)
    win.show()
    win.run_panel.out_edit.setText(str(tmp_path / "u.h5"))
    connect(qtbot, win)
    with qtbot.waitSignal(win.run_finished, timeout=60_000) as blocker:
        win.run_panel.start_button.click()
    assert blocker.args == ["unsafe"]
    assert win.bench_panel.status_label.text().startswith("✗ UNSAFE")
    qtbot.waitUntil(lambda: win.bench_panel.connect_button.isEnabled(), timeout=10_000)
    return win


def test_unsafe_goes_when_the_same_bench_is_reopened_with_its_addresses_retyped(
    qtbot: Any, tmp_path: Path
) -> None:
    """A physicist re-typed the bench file's addresses (the same generator and stage): the
    mark stayed up however often they read back off (the addresses were compared as
    written, case aside)."""
    win = _unsafe_lab_window(qtbot, tmp_path, "TCPIP0::192.168.1.10::INSTR", "COM4")
    retyped = _lab_bench(tmp_path / "retyped.yaml", " tcpip::192.168.1.10::inst0::instr ", "com4 ")
    assert win.load_bench(retyped)
    connect(qtbot, win)  # every output reads back off, the stage at rest
    label = win.bench_panel.status_label
    assert not label.text().startswith("✗ UNSAFE") and "b00000" not in label.styleSheet()
    assert any("UNSAFE is taken down" in line for line in win.log_view.lines[-3:])


def test_unsafe_stays_when_the_reopened_bench_names_another_stage_or_generator(
    qtbot: Any, tmp_path: Path
) -> None:
    """Another address keeps the mark up, the read-back off whatever: another serial device
    path (Linux names are case sensitive: /dev/ttyusb1 is not /dev/ttyUSB1; it had been
    upper-cased into the same), another host, the same host by another protocol."""
    win = _unsafe_lab_window(qtbot, tmp_path, "TCPIP0::192.168.1.10::INSTR", "/dev/ttyUSB1")
    label = win.bench_panel.status_label
    for n, (generator, stage) in enumerate(
        [
            ("TCPIP0::192.168.1.10::INSTR", "/dev/ttyusb1"),
            ("TCPIP0::192.168.1.11::INSTR", "/dev/ttyUSB1"),
            ("TCPIP0::192.168.1.10::hislip0::INSTR", "/dev/ttyUSB1"),
            ("TCPIP0::192.168.1.10::INSTR", "ASRL/dev/ttyUSB1::INSTR"),
        ]
    ):
        assert win.load_bench(_lab_bench(tmp_path / f"other{n}.yaml", generator, stage))
        connect(qtbot, win)  # read back off: of other instruments
        assert label.text().startswith("✗ UNSAFE"), (generator, stage)
        assert any("other instruments than the UNSAFE run's" in s for s in win.log_view.lines[-3:])
    # and the same instruments, written as the UNSAFE run's file wrote them, take it down
    assert win.load_bench(
        _lab_bench(tmp_path / "same.yaml", "TCPIP0::192.168.1.10::INSTR", "/dev/ttyUSB1 ")
    )
    connect(qtbot, win)
    assert not label.text().startswith("✗ UNSAFE")


def test_bench_identity_equates_only_spellings_of_one_resource() -> None:
    """The generator's VISA address and the stage's serial port, by the spellings that
    certainly open the same resource, and none that might not."""
    from daq.gui.main_window import _bench_identity
    from protocols.bench import parse_bench

    def identity(generator: str, stage: str) -> Any:
        return _bench_identity(parse_bench(_lab_text(generator, stage), "b"))

    base = identity("TCPIP0::192.168.1.10::INSTR", "ASRL4::INSTR")
    for generator, stage in [
        ("TCPIP::192.168.1.10::INSTR", "asrl4::instr"),
        ("TCPIP0::192.168.1.10::inst0::INSTR", " ASRL4::INSTR"),
        ("tcpip::192.168.1.10", "ASRL4::INSTR"),
        (" TCPIP0::192.168.1.10::INST0::instr\t", "Asrl4::Instr "),
    ]:
        assert identity(generator, stage) == base, (generator, stage)
    for stage in ["COM4", "ASRL4", "ASRL5::INSTR", "ASRL04::INSTR"]:  # pyserial's, or another
        assert identity("TCPIP0::192.168.1.10::INSTR", stage) != base, stage
    for generator in [
        "TCPIP1::192.168.1.10::INSTR",  # another network board
        "TCPIP0::192.168.1.10::hislip0::INSTR",  # another protocol (maybe, maybe not)
        "TCPIP0::192.168.1.10::5025::SOCKET",
        "TCPIP0::192.168.1.10::gpib0,5::INSTR",  # an instrument behind a LAN/GPIB gateway
        "TCPIP0::lab-awg.local::INSTR",  # a host name: no lookup
    ]:
        assert identity(generator, "ASRL4::INSTR") != base, generator
    com = identity("TCPIP0::192.168.1.10::INSTR", "COM4")
    assert identity("TCPIP0::192.168.1.10::INSTR", " com4") == com
    tty = identity("TCPIP0::192.168.1.10::INSTR", "/dev/ttyUSB1")
    assert identity("TCPIP0::192.168.1.10::INSTR", " /dev/ttyUSB1 ") == tty
    for other in ["/dev/ttyusb1", "/dev/serial/by-id/usb-FTDI_A1-if00", "ASRL/dev/ttyUSB1::INSTR"]:
        assert identity("TCPIP0::192.168.1.10::INSTR", other) != tty, other
    asrl_tty = identity("TCPIP0::192.168.1.10::INSTR", "ASRL/dev/ttyUSB1::INSTR")
    assert identity("TCPIP0::192.168.1.10::INSTR", "asrl/dev/ttyUSB1::instr") == asrl_tty
    assert identity("TCPIP0::192.168.1.10::INSTR", "ASRL/dev/ttyusb1::INSTR") != asrl_tty
