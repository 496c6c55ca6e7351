"""The compiled kernel's cache in the user's cache folder, and the notice while it compiles."""

from __future__ import annotations

import io
import subprocess
import sys
import time
from pathlib import Path

import pytest

from daq.cli.compile_notice import CompileNotice
from sim_backend.dem import kernel_cache

ROOT = Path(__file__).resolve().parents[2]
PROBE = "from sim_backend.dem import kernel; print(kernel.run_chunks._cache._cache_path)"


def _cache_path(env_dir: str) -> Path:
    import os

    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CACHE")}
    env["BIAFC_CACHE_DIR"] = env_dir
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, cwd=ROOT, capture_output=True,
                         text=True, check=True, timeout=120)  # fmt: skip
    return Path(out.stdout.strip().splitlines()[-1]).resolve()


def test_compiled_kernel_lives_in_the_user_cache_folder_not_the_sources(tmp_path: Path) -> None:
    path = _cache_path(str(tmp_path / "cache"))
    assert path.is_relative_to((tmp_path / "cache" / "numba").resolve())
    assert not path.is_relative_to(ROOT)


def test_unwritable_cache_folder_falls_back_without_failing(tmp_path: Path) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    path = _cache_path(str(blocker / "cache"))  # cannot be created: numba's own choice
    assert not path.is_relative_to(blocker.resolve())


def test_compile_notice_reports_start_progress_and_end(monkeypatch: pytest.MonkeyPatch) -> None:
    events: list[tuple[str, bool]] = []
    monkeypatch.setattr(kernel_cache, "kernel_loaded", lambda: False)
    monkeypatch.setattr(kernel_cache, "kernel_cached_on_disk", lambda: False)
    old = kernel_cache.set_compile_reporter(lambda ph, t, folder, cold: events.append((ph, cold)))
    try:
        with kernel_cache.compile_notice(tick_s=0.05):
            time.sleep(0.3)
    finally:
        kernel_cache.set_compile_reporter(old)
    phases = [p for p, _ in events]
    assert phases[0] == "start" and phases[-1] == "done" and "tick" in phases
    assert all(cold for _, cold in events)


def test_cli_notice_says_what_happens_and_that_it_happens_once(tmp_path: Path) -> None:
    buf = io.StringIO()
    notice = CompileNotice(buf)
    notice("start", 0.0, tmp_path, True)
    notice("done", 12.3, tmp_path, True)
    text = buf.getvalue()
    assert "compiling the DEM kernel" in text and "once" in text and str(tmp_path) in text
    assert "biafc warmup" in text and "12.3 s" in text


def test_biafc_warmup_command(capsys: pytest.CaptureFixture[str]) -> None:
    from daq.cli.biafc import main

    assert main(["warmup", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("warm: DEM kernel ready") and "cache" in out
