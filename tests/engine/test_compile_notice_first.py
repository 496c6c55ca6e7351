"""A fresh ``run_protocol smoke`` on the simulated bench with a cold kernel cache says that the
model compiles before it loads the heavy parts (numba, the kernel, scipy's solvers): the notice
comes within the first second of a command, not after seconds of imports (issue 19)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: a run_protocol that stops when the notice is out and says what was loaded by then
SCRIPT = """
import os, sys, time
t0 = time.perf_counter()
from daq.cli import compile_notice
shown = compile_notice.CompileNotice.__call__
HEAVY = ("numba", "sim_backend.dem.kernel", "sim_backend.dem.simulation", "scipy.interpolate",
         "scipy.optimize", "scipy.special", "scipy.linalg")

def call(self, phase, *args):
    shown(self, phase, *args)
    if phase == "start":
        loaded = [m for m in HEAVY if m in sys.modules]
        sys.stderr.write(f"AT NOTICE {time.perf_counter() - t0:.3f} s, loaded: {loaded}\\n")
        sys.stderr.flush()
        os._exit(0)

compile_notice.CompileNotice.__call__ = call
from daq.cli.run_protocol import main
main(sys.argv[1:])
sys.stderr.write("NO NOTICE\\n")
"""


def test_compile_notice_comes_before_the_heavy_imports(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CACHE")}
    env["BIAFC_CACHE_DIR"] = str(tmp_path / "cache")  # cold: no compiled kernel
    out = tmp_path / "run.h5"
    argv = [sys.executable, "-c", SCRIPT, "smoke", "--out", str(out)]
    proc = subprocess.run(argv, env=env, cwd=ROOT, capture_output=True, text=True, timeout=120)
    lines = proc.stderr.splitlines()
    assert proc.returncode == 0, proc.stderr
    assert lines[0].startswith("compiling the DEM kernel for this machine: once"), proc.stderr
    assert lines[1].startswith("AT NOTICE") and lines[1].endswith("loaded: []"), proc.stderr
    assert not out.exists()  # stopped before the run began
