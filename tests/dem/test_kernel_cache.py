"""The compiled kernel's cache in the user's cache folder, and the notice while it compiles."""

from __future__ import annotations

import hashlib
import io
import json
import os
import pickle
import re
import subprocess
import sys
import time
from importlib.metadata import version
from pathlib import Path

import pytest

from daq.cli.compile_notice import CompileNotice
from sim_backend.dem import kernel_cache
from tests.kernel_index import numba_cpu_name, write_fresh_index

ROOT = Path(__file__).resolve().parents[2]
PROBE = "from sim_backend.dem import kernel; print(kernel.run_chunks._cache._cache_path)"


def _cache_path(env_dir: str) -> Path:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CACHE")}
    env["BIAFC_CACHE_DIR"] = env_dir
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, cwd=ROOT, capture_output=True,
                         text=True, check=True, timeout=120)  # fmt: skip
    return Path(out.stdout.strip().splitlines()[-1]).resolve()


def test_compiled_kernel_lives_in_the_user_cache_folder_not_the_sources(tmp_path: Path) -> None:
    path = _cache_path(str(tmp_path / "cache"))
    assert path.is_relative_to((tmp_path / "cache" / "numba").resolve())
    assert not path.is_relative_to(ROOT)


#: prints {module.function: cache folder} of every cached numba function of the modules named
CACHE_FOLDERS = """
import importlib, json, sys
from numba.core.registry import CPUDispatcher
out = {}
for name in sys.argv[1:]:
    for key, obj in vars(importlib.import_module(name)).items():
        folder = getattr(getattr(obj, "_cache", None), "_cache_path", None)
        if isinstance(obj, CPUDispatcher) and obj.py_func.__module__ == name and folder:
            out[name + "." + key] = folder
print(json.dumps(out))
"""


def _modules_with_cached_functions() -> list[str]:
    """Every module of the project (sources, benchmarks, tests) that declares a numba function
    with ``cache=True``, found in the sources."""
    declares = re.compile(r"@numba\.njit\([^)]*cache=True")
    found = []
    for package in ("sim_backend", "benchmarks", "analysis", "daq", "instruments", "protocols",
                    "tests"):  # fmt: skip
        for path in sorted((ROOT / package).rglob("*.py")):
            if declares.search(path.read_text(encoding="utf-8")):
                found.append(".".join(path.relative_to(ROOT).with_suffix("").parts))
    return found


def test_every_cached_numba_function_compiles_into_the_user_cache_folder(tmp_path: Path) -> None:
    """Not only the kernel: a module whose functions numba decorates before the locator is
    installed caches next to its sources, and a read-only install whose home cache cannot be
    written fails on its first run ("cannot cache function 'drift_into': no locator available")."""
    modules = _modules_with_cached_functions()
    assert {"sim_backend.dem.kernel", "sim_backend.dem.split_steps"} <= set(modules)
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CACHE")}
    env["BIAFC_CACHE_DIR"] = str(tmp_path / "cache")
    out = subprocess.run([sys.executable, "-c", CACHE_FOLDERS, *modules], env=env, cwd=ROOT,
                         capture_output=True, text=True, check=True, timeout=300)  # fmt: skip
    folders = json.loads(out.stdout.strip().splitlines()[-1])
    assert {name.rsplit(".", 1)[0] for name in folders} == set(modules)
    user = (tmp_path / "cache" / "numba").resolve()
    elsewhere = {n: f for n, f in folders.items() if not Path(f).resolve().is_relative_to(user)}
    assert not elsewhere, f"cached outside {user}: {elsewhere}"


def test_unwritable_cache_folder_falls_back_without_failing(tmp_path: Path) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    path = _cache_path(str(blocker / "cache"))  # cannot be created: numba's own choice
    assert not path.is_relative_to(blocker.resolve())
    # and what biafc warmup says is where it is: it named the folder it could not write
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CACHE")}
    env["BIAFC_CACHE_DIR"] = str(blocker / "cache")
    probe = "from sim_backend.dem.kernel_cache import cache_note; print(cache_note())"
    out = subprocess.run([sys.executable, "-c", probe], env=env, cwd=ROOT, capture_output=True,
                         text=True, check=True, timeout=120).stdout.strip()  # fmt: skip
    assert out.startswith(f"cache {path}: the cache folder {blocker / 'cache' / 'numba'} cannot")
    assert "set $BIAFC_CACHE_DIR to a folder you can write" in out


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


def test_installed_notice_writes_to_the_stderr_of_the_moment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A notice installed while one stderr was current, and a compile after that stderr was
    replaced and closed (as a test harness's capture is), writes to the new one."""
    from daq.cli import compile_notice

    old = io.StringIO()
    monkeypatch.setattr(sys, "stderr", old)
    monkeypatch.setattr(kernel_cache, "_REPORTER", None)
    compile_notice.install()
    reporter = kernel_cache._REPORTER
    assert reporter is not None
    old.close()
    new = io.StringIO()
    monkeypatch.setattr(sys, "stderr", new)
    reporter("start", 0.0, tmp_path, True)
    reporter("done", 1.5, tmp_path, True)
    assert "DEM kernel ready after 1.5 s" in new.getvalue()


def test_biafc_warmup_command(capsys: pytest.CaptureFixture[str]) -> None:
    from daq.cli.biafc import main

    assert main(["warmup", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("warm: DEM kernel ready") and "cache" in out


def test_stale_compiled_files_are_another_lines_or_a_removed_modules(tmp_path: Path) -> None:
    """numba names a function's files by its first line: those of another line, and those of a
    module the sources no longer hold, are stale; another Python's and unknown files are kept."""
    sources = tmp_path / "src"
    sources.mkdir()
    (sources / "kernel.py").write_text("")
    folder = tmp_path / "cache"
    folder.mkdir()
    names = {
        "kernel.run_chunks-396.py311.nbi": False,  # the current source's
        "kernel.run_chunks-396.py311.1.nbc": False,
        "kernel.run_chunks-382.py311.nbi": True,  # an earlier source's
        "kernel.run_chunks-382.py311.1.nbc": True,
        "kernel.run_chunks-382.py312.nbi": False,  # another Python's
        "kernel.helper-10.py311.nbi": False,  # not loaded now: unknown
        "step_map._scan-234.py311.nbi": True,  # a module gone from the sources
        "step_map._scan-234.py311.2.nbc": True,
        "notes.txt": False,
    }
    for name in names:
        (folder / name).write_text("x")
    stale = kernel_cache.stale_compiled_files(folder, {"kernel.run_chunks": 396}, "py311", sources)
    assert sorted(p.name for p in stale) == sorted(n for n, s in names.items() if s)
    assert kernel_cache.stale_compiled_files(tmp_path / "missing", {}, "py311") == []


def test_a_process_first_run_removes_an_earlier_sources_compiled_kernel(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from instruments.burst import Burst
    from sim_backend import dem
    from sim_backend.dem import kernel

    folder = Path(kernel.run_chunks._cache._cache_path)
    current = folder / kernel.run_chunks._cache._cache_file._index_name
    tag = current.name.rsplit(".", 2)[1]
    planted = [
        folder / f"kernel.run_chunks-1.{tag}.nbi",
        folder / f"kernel.run_chunks-1.{tag}.1.nbc",
    ]
    folder.mkdir(parents=True, exist_ok=True)
    for path in planted:
        path.write_text("an earlier source's kernel")
    monkeypatch.setattr(kernel_cache, "_SWEPT", False)
    chain = dem.build_chain(dem.default_chain_spec())
    drive = dem.Drive("ltr", "displacement", chain.delta0_m, burst=Burst(8.92e3, 5.0))
    dem.simulate(chain, [drive], duration_s=1e-4)
    assert not any(path.exists() for path in planted)
    assert current.exists()
    assert kernel_cache.remove_stale_compiled() == []  # once per process


def test_where_the_kernel_is_looked_for_follows_numbas_fallback(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With a cache folder that cannot be written, numba keeps the kernel beside the sources,
    but the check for a compiled kernel still looked in the cache folder: every run announced
    a compile that did not happen (a second reader)."""
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("BIAFC_CACHE_DIR", str(blocker / "cache"))
    beside = Path(kernel_cache.__file__).resolve().parent / "__pycache__"
    assert kernel_cache.expected_cache_folder() == beside
    monkeypatch.setenv("BIAFC_CACHE_DIR", str(tmp_path / "new" / "cache"))  # can be made
    assert kernel_cache.expected_cache_folder() == tmp_path / "new" / "cache" / "numba"
    # and a kernel numba keeps there counts as on disk (every run announced a compile)
    there = tmp_path / "there"
    monkeypatch.setattr(kernel_cache, "expected_cache_folder", lambda: there)
    write_fresh_index(kernel_cache.kernel_index_folder() / "kernel.run_chunks-405.py311.nbi")
    assert kernel_cache.kernel_index_folder().parent == there
    assert kernel_cache.kernel_cached_on_disk()  # looked for where numba keeps it
    # another installation's subfolder of the same cache folder is not this one's (a fresh
    # clone counted another clone's index as its own: "estimated 00:00", then 9.8 s of compile)
    other = there / "dem_0123456789abcdef0123456789abcdef01234567"
    other.mkdir()
    index = kernel_cache.kernel_index_folder() / "kernel.run_chunks-405.py311.nbi"
    index.rename(other / index.name)
    assert not kernel_cache.kernel_cached_on_disk()


@pytest.mark.parametrize("command", ["regime", "compare", "calibrate", "figures", "check"])
def test_every_command_that_runs_the_dem_says_when_it_compiles(
    command: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A second reader: on an empty cache biafc regime, compare, calibrate and figures
    --alpha-sweep sat 11-13 s silent while the kernel compiled (only simulate, accuracy and
    stability said so)."""
    from daq.cli import compile_notice
    from daq.cli.biafc import main

    installed: list[bool] = []
    monkeypatch.setattr(compile_notice, "install", lambda stream=None: installed.append(True))
    with pytest.raises(SystemExit):
        main([command, "--help"])
    assert installed == [True]


def test_a_stale_index_is_no_compiled_kernel(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A fresh clone's first run estimated 00:00 and then compiled for 11.4 s: an index left in
    its cache folder by other sources (numba keys it by the source's sha256) counted as a
    compiled kernel."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    index = kernel_cache.kernel_index_folder() / "kernel.run_chunks-404.py311.nbi"
    source = Path(kernel_cache.__file__).with_name("kernel.py").read_bytes()
    assert not kernel_cache.kernel_cached_on_disk()  # nothing there
    write_fresh_index(index, sources=source + b"# older")
    assert not kernel_cache.kernel_cached_on_disk()  # other sources
    write_fresh_index(index, numba="0.1.0")
    assert not kernel_cache.kernel_cached_on_disk()  # another numba
    write_fresh_index(index, cpu="some-other-cpu")
    assert not kernel_cache.kernel_cached_on_disk()  # compiled on another machine
    index.write_bytes(b"")
    assert not kernel_cache.kernel_cached_on_disk()  # truncated
    write_fresh_index(index)
    assert kernel_cache.kernel_cached_on_disk()


#: a module with one cached numba function, compiled on import (spelt so that
#: _modules_with_cached_functions does not take this test module for one)
TINY = """from numba import njit


@njit(cache=True)
def tiny(x):
    return x + 1


tiny(1)
"""


def _index_numba_writes(tmp_path: Path) -> tuple[Path, bytes]:
    """Compile :data:`TINY` in a process of its own with this environment (its CPU name) into
    a cache folder under ``tmp_path``: the index numba wrote and the sha256 it stamped it with."""
    source = tmp_path / "src" / "tiny_cached.py"
    source.parent.mkdir()
    source.write_text(TINY, encoding="utf-8")
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CACHE")}
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "cache")
    subprocess.run([sys.executable, str(source)], env=env, cwd=tmp_path, capture_output=True,
                   check=True, timeout=60)  # fmt: skip
    (index,) = (tmp_path / "cache").rglob("tiny_cached.tiny-*.nbi")
    return index, hashlib.sha256(source.read_bytes()).digest()


@pytest.mark.parametrize(
    "cpu_env",
    [
        None,
        "generic",
        "",  # numba keys by '' (its config.CPU_NAME is not None); the product had the host's
    ],
)
def test_the_cpu_of_an_index_numba_wrote_is_the_one_the_product_looks_for(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, cpu_env: str | None
) -> None:
    """The product's CPU name against a real index: numba keys each compiled overload by the
    CPU it compiled for (``$NUMBA_CPU_NAME``, else LLVM's host CPU); a product that names
    another CPU (or spells it otherwise) announces a compile at every run, or takes another
    machine's kernel for this one's."""
    if cpu_env is None:
        monkeypatch.delenv("NUMBA_CPU_NAME", raising=False)
    else:
        monkeypatch.setenv("NUMBA_CPU_NAME", cpu_env)
    index, stamp = _index_numba_writes(tmp_path)
    with index.open("rb") as f:
        numba_version = pickle.load(f)
        _, overloads = pickle.loads(f.read())
    written = {key[1][1] for key in overloads}  # key: (signature, magic tuple, hashes)
    assert written == {numba_cpu_name()}  # the helper's name is numba's
    cpu = kernel_cache._cpu_name()
    assert cpu is not None and {cpu.decode()} == written
    assert numba_version == version("numba")
    assert kernel_cache._fresh_index(index, stamp, numba_version, cpu)
    # the helper's index of these sources: numba's key, fresh; for another CPU, not
    source = (tmp_path / "src" / "tiny_cached.py").read_bytes()
    mine = tmp_path / "helper" / "tiny_cached.tiny-4.py311.nbi"
    write_fresh_index(mine, sources=source)
    with mine.open("rb") as f:
        pickle.load(f)
        _, mine_overloads = pickle.loads(f.read())
    # triple and CPU (the features are those of this process's first codegen)
    assert {key[1][:2] for key in mine_overloads} == {key[1][:2] for key in overloads}
    assert kernel_cache._fresh_index(mine, stamp, numba_version, cpu)
    write_fresh_index(mine, sources=source, cpu="another-cpu")
    assert not kernel_cache._fresh_index(mine, stamp, numba_version, cpu)


@pytest.mark.parametrize(
    ("written", "asked"), [("skylake-avx512", "skylake"), ("znver5", "znver"), ("znver5", "x")]
)
def test_an_index_for_another_cpu_whose_name_holds_this_ones_is_no_compiled_kernel(
    tmp_path: Path, written: str, asked: str
) -> None:
    """The CPU is matched as a whole name: the check had looked for its bytes anywhere in the
    index, so a kernel compiled for ``skylake-avx512`` counted as compiled on a ``skylake``
    (numba would compile, after an estimate without the compile), and ``x`` was found in
    ``x86_64``."""
    nbi = tmp_path / "kernel.run_chunks-1.py311.nbi"
    write_fresh_index(nbi, cpu=written)
    kernel_py = Path(__file__).resolve().parents[2] / "sim_backend" / "dem" / "kernel.py"
    stamp = hashlib.sha256(kernel_py.read_bytes()).digest()
    assert kernel_cache._fresh_index(nbi, stamp, version("numba"), written.encode())
    assert not kernel_cache._fresh_index(nbi, stamp, version("numba"), asked.encode())
