"""One progress display (daq.progress) for every command: a live rich bar with rate and ETA on a
terminal, plain lines when piped; run_protocol shows the engine's progress through it."""

from __future__ import annotations

import io
import math
from pathlib import Path
from types import SimpleNamespace

import pytest

import daq.connect
from daq.cli import run_protocol as rp
from daq.progress import ProgressDisplay, format_duration, format_minutes, format_rate

from .fakes import FakeWorld, fake_bench
from .helpers import PROTOCOL


class Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_plain_lines_when_piped() -> None:
    s = io.StringIO()
    with ProgressDisplay(3, unit="run", stream=s, plain_every_s=3600) as p:
        p.update(1, detail="a")
        p.update(2, detail="b")  # within the interval: not printed
        p.update(3, detail="c", eta_s=0.0)  # the last one always is
    lines = s.getvalue().splitlines()
    assert len(lines) == 2
    assert lines[0].startswith("run 1/3: a, ")
    assert "runs/s" in lines[0] or "s/run" in lines[0]
    assert lines[1].startswith("run 3/3: c, ") and lines[1].endswith("ETA 00:00")
    assert "\x1b[" not in s.getvalue()  # no terminal codes in a log


def test_live_bar_on_a_terminal() -> None:
    s = Tty()
    with ProgressDisplay(4, unit="point", label="measuring", stream=s) as p:
        p.update(2, detail="ltr cyl 2", eta_s=75.0)
        p.note("warning: something")
        p.update(4, detail="ltr cyl 4", eta_s=0.0)
    text = s.getvalue()
    assert "\x1b[" in text and "━" in text  # a drawn bar
    assert "measuring" in text and "4/4" in text and "points/s" in text
    assert "ETA" in text and "warning: something" in text


def test_the_rate_leaves_out_what_came_before_the_first_item(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The first point carries homing and the model's compile: 15 s, then 0.1 s a point. The
    rate read from the start said 3.1 s/point after 5 points (and ETA from it 10x too long);
    it now reads 10 points/s from the first point on."""
    import daq.progress

    now = [100.0]
    monkeypatch.setattr(daq.progress, "time", SimpleNamespace(monotonic=lambda: now[0]))
    s = io.StringIO()
    with ProgressDisplay(10, stream=s, plain_every_s=0.0) as p:
        now[0] += 15.0
        p.update(1)
        assert p.rate_text() == "15 s/point"  # one point: all there is to go on
        for k in range(2, 6):
            now[0] += 0.1
            p.update(k)
        assert p.rate_text() == "10 points/s"
        assert p.eta_from_rate() == pytest.approx(0.5)


def test_work_in_waves_counts_its_rate_from_the_end_of_the_first_wave(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Eight workers end their first tasks within milliseconds of each other: counted from the
    first of them, the rate read 1000 items/s and the ETA 1.5 s where 95 s were left."""
    import daq.progress

    now = [0.0]
    monkeypatch.setattr(daq.progress, "time", SimpleNamespace(monotonic=lambda: now[0]))
    with ProgressDisplay(160, stream=io.StringIO(), steady_after=8) as p:
        for wave in range(2):
            now[0] += 10.0 if wave == 0 else 5.0  # start-up, then 5 s a task
            for k in range(8):
                now[0] += 0.001
                p.update(8 * wave + k + 1)
        assert p.eta_from_rate() == pytest.approx(144 * 5.0 / 8, rel=0.01)  # 90 s


def test_quiet_prints_nothing() -> None:
    s = Tty()
    with ProgressDisplay(2, stream=s, quiet=True) as p:
        p.update(1)
        p.note("x")
    assert s.getvalue() == ""


def test_formats() -> None:
    assert format_duration(75.4) == "01:15" and format_duration(3725) == "1:02:05"
    assert format_duration(float("inf")) == "--:--"
    assert format_rate(10, 2.0, "point") == "5 points/s"
    assert format_rate(1, 12.0, "point") == "12 s/point"
    # a bound: rounded up (20.4 s is "at most 21 s"), not down; not finite said so
    assert format_minutes(20.4) == "21 s" and format_minutes(20.000001) == "20 s"
    assert format_minutes(150.0) == "2 min 30 s" and format_minutes(math.inf) == "an unknown time"


@pytest.mark.parametrize("tty", [True, False])
def test_run_protocol_progress(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, tty: bool) -> None:
    monkeypatch.setattr(daq.connect, "connect_bench", lambda bf, **k: fake_bench(FakeWorld()))
    proto = tmp_path / "p.yaml"
    proto.write_text(PROTOCOL)
    stream = Tty() if tty else io.StringIO()
    monkeypatch.setattr("sys.stdout", stream)
    assert rp.main([str(proto), "--out", str(tmp_path / "o.h5")]) == 0
    text = stream.getvalue()
    assert "complete: 12 points" in text and "estimated" in text
    if tty:
        assert "━" in text and "12/12" in text and "ETA" in text and "points/s" in text
    else:
        assert "point 12/12: rtl 2 Vpp cyl  3, " in text and "\x1b[" not in text
