"""A run on a lab bench keeps the computer from sleeping (:mod:`daq.engine.keep_awake`): a PC
set to sleep after idle minutes stopped an overnight run where it stood. The system calls are
replaced by stand-ins: kernel32 as Microsoft documents ``SetThreadExecutionState``, and a
``systemd-inhibit`` script that holds while it runs (the real one needs a session bus)."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import pytest

from daq.engine import RunEngine
from daq.engine import engine as engine_module
from daq.engine.keep_awake import keep_awake
from protocols.bench import load_bench

from .fakes import FakeWorld, fake_bench

ROOT = Path(__file__).resolve().parents[2]


#: SetThreadExecutionState's flags as Microsoft documents them (winbase.h), not the module's
ES_CONTINUOUS = 0x80000000
ES_SYSTEM_REQUIRED = 0x00000001


class Kernel32:
    def __init__(self, answer: int = 1) -> None:
        self.calls: list[int] = []
        self.answer = answer

    def SetThreadExecutionState(self, flags: int) -> int:
        self.calls.append(flags)
        return self.answer


def test_windows_asks_the_system_to_stay_up_and_resets_it_after() -> None:
    k = Kernel32()
    with keep_awake(kernel32=k) as (holder, why_not):
        assert holder is not None and why_not is None
        assert k.calls == [ES_CONTINUOUS | ES_SYSTEM_REQUIRED]
    assert k.calls == [ES_CONTINUOUS | ES_SYSTEM_REQUIRED, ES_CONTINUOUS]
    refused = Kernel32(answer=0)
    with keep_awake(kernel32=refused) as (holder, why_not):
        assert holder is None and why_not == "SetThreadExecutionState refused"
    assert refused.calls[-1] == ES_CONTINUOUS  # reset all the same


def _script(folder: Path, body: str) -> Path:
    path = folder / "systemd-inhibit"
    path.write_text("#!/bin/sh\n" + body)
    path.chmod(0o755)
    return path


@pytest.mark.skipif(os.name != "posix", reason="a shell script stands in for systemd-inhibit")
def test_linux_holds_an_inhibitor_for_the_block_and_ends_it(tmp_path: Path) -> None:
    args = tmp_path / "args"
    tool = _script(tmp_path, f'echo "$@" > {args}\nexec sleep 1000\n')
    with keep_awake(which=lambda name: str(tool), platform="linux") as (holder, why_not):
        assert holder == "systemd-inhibit --what=sleep:idle" and why_not is None
        said = args.read_text()
        assert "--what=sleep:idle" in said and "--mode=block" in said
        assert _sleeping(args)  # the stand-in holds while the block runs
    t_end = time.monotonic() + 5
    while time.monotonic() < t_end and _sleeping(args):
        time.sleep(0.05)
    assert not _sleeping(args)  # the inhibitor ended with the block


def _sleeping(marker: Path) -> bool:
    """Whether a ``sleep 1000`` started by the stand-in still runs."""
    for pid in os.listdir("/proc"):
        try:
            if Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[:2] == [b"sleep", b"1000"]:
                return True
        except OSError:
            continue
    return False


@pytest.mark.skipif(os.name != "posix", reason="a shell script stands in for systemd-inhibit")
def test_an_inhibitor_that_cannot_hold_is_named(tmp_path: Path) -> None:
    tool = _script(tmp_path, 'echo "Failed to connect to bus: No such file" >&2\nexit 1\n')
    with keep_awake(which=lambda name: str(tool), platform="linux") as (holder, why_not):
        assert holder is None
        assert why_not == "systemd-inhibit: Failed to connect to bus: No such file"
    with keep_awake(which=lambda name: None, platform="linux") as (holder, why_not):
        assert holder is None and why_not == "no caffeinate or systemd-inhibit here"


@pytest.mark.parametrize("bench_name", ["lab_bench.yaml", "sim_bench.yaml"])
def test_a_lab_benchs_run_keeps_the_computer_awake_a_simulated_one_does_not(
    protocol: Any, bench_name: str, out: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    held: list[str] = []

    from contextlib import contextmanager

    @contextmanager
    def hold() -> Any:
        held.append("held")
        yield "a stand-in", None
        held.append("let go")

    monkeypatch.setattr(engine_module, "keep_awake", hold)
    bench = load_bench(ROOT / "protocols" / "benches" / bench_name)
    res = RunEngine(protocol, bench, fake_bench(FakeWorld()), out).run()
    assert res.status == "complete", res.reason
    if bench_name == "lab_bench.yaml":
        assert held == ["held", "let go"]
        assert any("kept awake during the run (a stand-in)" in m for m in _log_of(out))
    else:
        assert held == []


def _log_of(path: Path) -> list[str]:
    from protocols.runfile import read_run

    return [m for _, _, m in read_run(path).log]
