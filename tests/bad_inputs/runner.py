"""Run one bad-input case the way a person at the bench would meet it: the real command-line
entry point (``run_protocol`` or ``biafc``) in this process, in a scratch folder, with every
instrument connection forbidden. The :class:`Outcome` holds what the invariants look at."""

from __future__ import annotations

import contextlib
import io
import os
import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import pytest

from .cases import Case, Sources

#: every refusal within this wall time (s) ...
MAX_SECONDS = 2.0
#: ... and this much memory at its peak (bytes of resident memory above the start)
MAX_BYTES = 500 * 2**20
_PAGE = os.sysconf("SC_PAGE_SIZE")


def _rss() -> int:
    with open("/proc/self/statm", "rb") as f:
        return int(f.read().split()[1]) * _PAGE


class _PeakMemory:
    """The peak resident memory of this process above its value at the start (bytes),
    sampled every 5 ms in a thread (0 where /proc is missing)."""

    def __enter__(self) -> _PeakMemory:
        self.peak = 0
        try:
            self.base = _rss()
        except OSError:
            self.base = None
            return self
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)
        self._thread.start()
        return self

    def _sample(self) -> None:
        while not self._stop.wait(0.005):
            self.peak = max(self.peak, _rss() - (self.base or 0))

    def __exit__(self, *exc: object) -> None:
        if self.base is not None:
            self._stop.set()
            self._thread.join()
            self.peak = max(self.peak, _rss() - self.base)


@dataclass
class Outcome:
    """What a case did: exit status, its stdout and stderr, an escaped exception's traceback
    (empty if none), wall time (s), peak traced memory (bytes), whether an instrument
    connection was attempted, and the paths added or changed in the scratch folder."""

    code: int | None
    stdout: str
    stderr: str
    escaped: str
    seconds: float
    peak_bytes: int
    connected: bool
    written: list[str]

    def one_line(self) -> str:
        return self.stderr.strip()


class _Connected(Exception):
    """Raised by the stand-in for daq.connect.connect_bench: an instrument would be opened."""


def tree(root: Path) -> dict[str, tuple[int, int]]:
    """Every path under ``root`` with its size and mtime: compared before and after a case
    to see that nothing was written."""
    out: dict[str, tuple[int, int]] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st = p.lstat()
            out[str(p.relative_to(root))] = (st.st_size, st.st_mtime_ns)
    return out


def _main(prog: str):  # type: ignore[no-untyped-def]
    if prog == "run_protocol":
        from daq.cli.run_protocol import main

        return main
    if prog == "biafc":
        from daq.cli.biafc import main

        return main
    raise ValueError(f"unknown program {prog!r}")


def run_case(
    case: Case, folder: Path, sources: Sources, monkeypatch: pytest.MonkeyPatch
) -> Outcome:
    """Write the case's files into ``folder`` and run its command line there."""
    import daq.connect

    for name, content in case.files.items():
        data = content(sources) if callable(content) else content
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data.encode() if isinstance(data, str) else data)
    connected: list[bool] = []

    def forbidden(*args: object, **kwargs: object) -> None:
        connected.append(True)
        raise _Connected("an instrument connection was attempted")

    monkeypatch.setattr(daq.connect, "connect_bench", forbidden)
    monkeypatch.chdir(folder)
    before = tree(folder)
    prog, *argv = case.argv
    main = _main(prog)
    out, err = io.StringIO(), io.StringIO()
    code: int | None = None
    escaped = ""
    t0 = time.perf_counter()
    with _PeakMemory() as memory:
        try:
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                try:
                    code = int(main(list(argv)) or 0)
                except SystemExit as exc:
                    code = exc.code if isinstance(exc.code, int) else 1
        except BaseException:  # a traceback is what the case must not produce
            escaped = traceback.format_exc()
        seconds = time.perf_counter() - t0
    peak = memory.peak
    after = tree(folder)
    written = sorted(p for p, st in after.items() if before.get(p) != st)
    return Outcome(code, out.getvalue(), err.getvalue(), escaped, seconds, peak,
                   bool(connected), written)  # fmt: skip


def check_refused(case: Case, outcome: Outcome) -> None:
    """The invariants of a refusal: exit 2, exactly one line on stderr naming what the case
    expects, no traceback, no instrument, nothing written, within time and memory bounds."""
    assert not outcome.escaped, f"an exception escaped:\n{outcome.escaped}"
    assert not outcome.connected, "an instrument connection was attempted"
    lines = outcome.stderr.strip().splitlines()
    assert outcome.code == 2, f"exit {outcome.code}, stderr: {outcome.stderr!r}"
    assert len(lines) == 1, f"expected one line on stderr, got {outcome.stderr!r}"
    assert "Traceback" not in outcome.stderr + outcome.stdout
    for fragment in case.expect:
        assert fragment in lines[0], f"{fragment!r} not in {lines[0]!r}"
    assert not outcome.written, f"written: {outcome.written}"
    assert outcome.seconds < MAX_SECONDS, f"took {outcome.seconds:.2f} s"
    assert outcome.peak_bytes < MAX_BYTES, f"peak {outcome.peak_bytes / 2**20:.0f} MiB"
