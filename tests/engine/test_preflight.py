"""``biafc check``: the preflight on the simulated bench, a deliberate mismatch named, the
burst of ``--move``, and the carrier estimate it relies on."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import daq.connect
from daq.cli.biafc import main
from daq.preflight import measured_carrier_Hz
from instruments.burst import Burst


def _connected(monkeypatch: pytest.MonkeyPatch, change: Any = None) -> list[Any]:
    """Keep what ``connect_bench`` returned; ``change(bench)`` then alters the instruments."""
    made: list[Any] = []
    real = daq.connect.connect_bench

    def keep(*a: Any, **k: Any) -> Any:
        bench = real(*a, **k)
        if change is not None:
            change(bench)
        made.append(bench)
        return bench

    monkeypatch.setattr(daq.connect, "connect_bench", keep)
    return made


def test_check_on_the_shipped_simulated_bench_passes(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    made = _connected(monkeypatch)
    assert main(["check"]) == 0
    out = capsys.readouterr().out
    assert "sim_bench.yaml" in out and "every instrument matches the bench file" in out
    for row in (
        "33522B",
        "4.00-1.19-2.00-58-00",
        "VD-09 50mm/s/V",
        "microstep",
        "travel",
        "31 cylinders",
        "terminal configuration",
        "rate per channel",
    ):
        assert row in out, row
    assert "MISMATCH" not in out
    world = made[0].world
    assert world.clock.now() == pytest.approx(world.clock.now())  # nothing ran on the rig
    assert not world._inst.stage.busy() and not world._inst.stage.homed


def test_check_names_a_deliberate_mismatch(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Someone turned the vibrometer's range knob and pressed generator output 2 (on the
    emulated instruments themselves, not through the drivers)."""

    def tamper(bench: Any) -> None:
        bench.world._inst.vibrometer.range_value = "10mm/s/V"
        bench.world._inst.generator.channels[2].output_on = True

    _connected(monkeypatch, tamper)
    assert main(["check"]) == 1
    cap = capsys.readouterr()
    lines = [ln for ln in cap.out.splitlines() if re.match(r"MISMATCH \S", ln)]  # the summary
    assert len(lines) == 2, cap.out
    assert lines[0].startswith(
        "MISMATCH generator output 2 (rtl): ON (bench file: off): an output is on"
    )
    assert lines[1].startswith(
        "MISMATCH vibrometer velocity range: VD-09 10mm/s/V (bench file: VD-09 50mm/s/V)"
    )
    assert "2 mismatch(es)" in cap.err


def test_check_names_a_signal_level_above_the_bench_files_full_scale(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A controller whose level reads up to 775 against the bench file's 100: a mismatch naming
    the field, the vibrometer's other findings kept (before, the bench file could not name the
    scale and the driver clipped every level above it to 1.0)."""

    def larger_scale(bench: Any) -> None:
        bench.world._inst.vibrometer.level_scale = 775

    _connected(monkeypatch, larger_scale)
    assert main(["check"]) == 1
    cap = capsys.readouterr()
    lines = [ln for ln in cap.out.splitlines() if re.match(r"MISMATCH \S", ln)]
    assert len(lines) == 1, cap.out
    assert re.match(
        r"MISMATCH vibrometer signal level here: signal level \d+ is above the full scale 100 "
        r"\(bench file: level_full_scale 100\): set vibrometer\.level_full_scale",
        lines[0],
    ), lines[0]
    assert "VD-09 50mm/s/V" in cap.out  # the range's finding still shown


def test_check_move_fires_one_burst_and_leaves_the_bench_safe(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    made = _connected(monkeypatch)
    assert main(["check", "--move", "--cylinder", "2"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"^ok\s+bench\s+safe state after the burst\s+.*confirmed$", out, re.M)
    assert re.search(r"^ok\s+burst\s+signal level at cylinder 2", out, re.M)
    assert re.search(r"^ok\s+burst\s+output 1 load\s+high Z \(INF\)\s+high Z \(INF\)", out, re.M)
    assert re.search(r"^ok\s+burst\s+velocity peak\s+[\d.]+ mm/s", out, re.M)
    m = re.search(r"carrier on the drive reference\s+8920 Hz\s+([\d.]+) Hz", out)
    assert m is not None, out
    assert abs(float(m.group(1)) - 8920.0) / 8920.0 < 5e-4  # the generator plays it at 8920 Hz
    assert re.search(r"^ok\s+burst\s+carrier on the drive reference", out, re.M)
    world = made[0].world
    emu = world._inst
    assert emu.stage.homed and world.n_acquisitions == 1
    assert not any(ch.output_on for ch in emu.generator.channels.values())
    pos = float(emu.stage.position_m())
    assert pos == pytest.approx(float(world.cylinder_positions_m[1]), abs=1e-5)


def test_check_move_names_a_safe_state_it_could_not_confirm_exit_3(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """After the burst the outputs are read back and the stage asked whether it came to rest,
    as at a run's end; before, check --move called each safe state and said nothing of it."""

    import daq.preflight

    burst = daq.preflight.check_burst

    def then_stuck(bf: Any, inst: Any, test: Any) -> Any:  # the burst leaves them stuck
        found = burst(bf, inst, test)
        inst.stage.is_moving = lambda: True
        inst.generator.output_state = lambda ch: True  # an output stuck on
        return found

    monkeypatch.setattr(daq.preflight, "check_burst", then_stuck)
    assert main(["check", "--move", "--cylinder", "2"]) == 3
    cap = capsys.readouterr()
    assert "MISMATCH bench safe state after the burst" in cap.out
    last = cap.err.strip().splitlines()[-1]
    assert last.startswith("biafc check: UNSAFE: SWITCH OFF BY HAND:"), last
    assert "output 1: still ON" in last and "stage controller" in last


def test_check_move_says_a_silent_stage_and_confirms_after_any_error(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A stage that does not answer whether it stopped read as 'confirmed' (exit 0); an error
    the burst test did not expect (an OSError, a stop signal) left without reading anything
    back, and an OSError ended in a traceback: now a finding of one line, then the unsafe
    end (exit 3)."""
    from daq import preflight
    from instruments.errors import InstrumentTimeout

    def silent(bench: Any) -> None:
        def no_reply() -> bool:
            raise InstrumentTimeout("stage: no reply to 'get pos'")

        bench.stage.is_moving = no_reply

    _connected(monkeypatch, silent)
    assert main(["check", "--move", "--cylinder", "2"]) == 1
    out = capsys.readouterr().out
    assert "MISMATCH bench safe state after the burst: outputs confirmed off; stage: cannot " in out

    def stuck(bench: Any) -> None:
        bench.stage.is_moving = lambda: True

    def broken(*a: Any) -> Any:
        raise OSError("the card's driver crashed")

    _connected(monkeypatch, stuck)
    monkeypatch.setattr(preflight, "check_burst", broken)
    assert main(["check", "--move", "--cylinder", "2"]) == 3
    out, err = capsys.readouterr()
    assert "MISMATCH burst one burst: OSError: the card's driver crashed" in out, out
    assert "biafc check: UNSAFE: SWITCH OFF BY HAND: stage controller" in err, err
    assert "Traceback" not in out + err

    def interrupted(*a: Any) -> Any:
        raise KeyboardInterrupt

    _connected(monkeypatch, stuck)
    monkeypatch.setattr(preflight, "check_burst", interrupted)
    # a stop signal still leaves at once (Ctrl-C: 130), said unsafe first
    assert main(["check", "--move", "--cylinder", "2"]) == 130
    err = capsys.readouterr().err
    assert "biafc check: UNSAFE: SWITCH OFF BY HAND: stage controller" in err, err
    assert err.rstrip().endswith("biafc check: interrupted"), err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["check", "no_such_bench.yaml"], "no_such_bench.yaml"),
        (["check", "--move", "--amplitude", "20 Vpp"], "above the generator limit"),
        (["check", "--move", "--amplitude", "2"], "--amplitude"),
        (["check", "--move", "--amplitude", "0.2 V"], "(0.2 Vpp) or peak (0.2 Vpk)"),
        (["check", "--move", "--amplitude", "1 um"], "give generator volts"),
        (["check", "--move", "--cylinder", "32"], "choose 1..31"),
    ],
)
def test_refused_requests_are_one_line_and_exit_2(
    args: list[str],
    message: str,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    made = _connected(monkeypatch)
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not made  # refused before anything was connected


def test_the_test_bursts_amplitude_is_checked_as_the_driver_checks_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The five-cycle test burst's peaks are unequal (x1.088 of half its Vpp under one reading
    of the generator's amplitude): 4.8 Vpp on a 50 V piezo at gain 20 passed the request's check
    at 48 V, homed and moved the stage, then was refused by the driver as a 'MISMATCH'."""
    from protocols.bench import load_bench

    bench = tmp_path / "bench.yaml"
    bench.write_text(load_bench().text.replace("piezo_max: 150 V", "piezo_max: 50 V"))
    made = _connected(monkeypatch)
    assert main(["check", str(bench), "--move", "--amplitude", "4.8 Vpp"]) == 2
    err = capsys.readouterr().err.strip()
    assert "gives up to 52.2 V at the piezo" in err and "x1.088" in err, err
    assert not made


@pytest.mark.parametrize("rate", [200e3, 1e6])
@pytest.mark.parametrize("f_c", [8.92e3, 6.63e3])
def test_the_carrier_of_a_burst_played_at_another_rate_is_measured(rate: float, f_c: float) -> None:
    played = f_c * (1 - 9e-4)  # a generator playing its points 0.09 % slow
    t = np.arange(2200) / rate
    x = 0.7 * Burst(played, cycles=5).at(t - 123.4 / rate) + 0.01
    assert measured_carrier_Hz(x, rate, Burst(f_c, cycles=5)) == pytest.approx(played, rel=1e-6)
    noisy = x + np.random.default_rng(1).normal(0.0, 1e-3, x.size)
    assert measured_carrier_Hz(noisy, rate, Burst(f_c, cycles=5)) == pytest.approx(played, rel=3e-4)


def test_check_shows_the_errors_the_generator_held_when_it_connected(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A second reader: the connect's *CLS emptied the queue before the check read it, so the
    row always said "empty"."""
    from sim_backend.emulators import keysight

    made = keysight.KeysightEmulator.__init__

    def left_by_someone(self: Any, *a: Any, **k: Any) -> None:
        made(self, *a, **k)
        self.push_error(-222, "Data out of range")

    monkeypatch.setattr(keysight.KeysightEmulator, "__init__", left_by_someone)
    assert main(["check"]) == 0  # said, not a mismatch: cleared at connect (a reviewer)
    out = capsys.readouterr().out
    assert re.search(r"errors before connecting\s+-222,\"?Data out of range", out), out
    assert "cleared at connect" in out


def test_check_move_does_not_move_or_fire_on_a_generator_that_does_not_match(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A second reader: --move homed the stage and fired a burst whatever the read-only check
    found (here an output already on)."""

    def pressed(bench: Any) -> None:
        bench.world._inst.generator.channels[2].output_on = True

    made = _connected(monkeypatch, pressed)
    assert main(["check", "--move", "--cylinder", "2"]) == 1
    out = capsys.readouterr().out
    assert re.search(r"^MISMATCH\s+burst\s+one burst.*not fired", out, re.M), out
    assert "generator output 2 (rtl)" in out
    world = made[0].world
    assert not world._inst.stage.homed and world.n_acquisitions == 0


def test_check_refuses_a_missing_driver_as_run_protocol_does(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A second reader: a missing NI-DAQmx driver was exit 2 from run_protocol and exit 1 from
    biafc check, and it was found after the three instruments had been opened."""
    import instruments.transport
    from daq import digitiser_nidaq
    from instruments.errors import DriverNotInstalledError

    def missing() -> Any:
        raise DriverNotInstalledError("NI-DAQmx driver not installed or not loadable")

    opened: list[str] = []
    monkeypatch.setenv("BIAFC_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(digitiser_nidaq, "_load_nidaqmx", missing)
    monkeypatch.setattr(instruments.transport, "open_transport", lambda r, **k: opened.append(r))
    lab = Path(__file__).resolve().parents[2] / "protocols" / "benches" / "lab_bench.yaml"
    assert main(["check", str(lab)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("biafc check: refused: NI-DAQmx driver not installed"), err
    assert opened == []


def test_an_instrument_error_without_a_message_is_one_line_exit_1(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A connect that fails with an empty message (a driver's bare ``InstrumentError()``) ended
    ``biafc check`` in an IndexError's traceback: the message's first line of nothing."""
    from instruments.errors import InstrumentError

    def fail(*a: Any, **k: Any) -> Any:
        raise InstrumentError()

    monkeypatch.setattr(daq.connect, "connect_bench", fail)
    assert main(["check"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["biafc check: cannot connect: InstrumentError"], err
