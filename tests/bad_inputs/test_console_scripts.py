"""A few bad-input cases through the installed console scripts, in a process of their own, as
a person types them: the entry points add nothing to the one line (issue 16). The in-process
runner (test_cases.py) holds the 2 s bound; here the bound includes Python's start."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from .cases import CASES, Sources

SCRIPTS = Path(sys.executable).parent
CHOSEN = ("protocol_laughs", "figures_1kB", "resume_damaged", "simulate_dt_50us")


@pytest.mark.parametrize("name", CHOSEN)
def test_console_script_refuses_in_one_line(name: str, tmp_path: Path, sources: Sources) -> None:
    case = next(c for c in CASES if c.name == name)
    prog, *argv = case.argv
    script = SCRIPTS / prog
    if not script.exists() and shutil.which(prog) is None:
        pytest.skip(f"{prog} is not installed as a console script here")
    for file, content in case.files.items():
        data = content(sources) if callable(content) else content
        (tmp_path / file).write_bytes(data.encode() if isinstance(data, str) else data)
    before = sorted(os.listdir(tmp_path))
    run = subprocess.run(
        [str(script if script.exists() else prog), *argv],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=60,
    )
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2, run.stderr
    assert len(lines) == 1 and "Traceback" not in run.stderr, run.stderr
    assert all(f in lines[0] for f in case.expect), lines[0]
    assert sorted(os.listdir(tmp_path)) == before


def test_python_dash_m_refuses_in_one_line_as_the_console_script(tmp_path: Path) -> None:
    """``python -m daq.cli.biafc`` ran the module as a second copy of itself, whose CliError
    the commands' refusals were not: they came out as tracebacks (exit 1)."""
    argv = ["simulate", "--direction", "ltr", "--amplitude", "1 um", "--out", "x.h5"]
    run = subprocess.run(
        [sys.executable, "-m", "daq.cli.biafc", *argv, "--rate", "10 kS/s"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])},
    )
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and len(lines) == 1, run.stderr
    assert "above the Nyquist frequency 5 kHz" in lines[0]
