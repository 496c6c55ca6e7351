"""Run Python code in a fresh interpreter, as a user's command starts: for tests of what a
process imports, loads or leaves behind."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path


def python_c(
    code: str,
    *args: str,
    cwd: Path | None = None,
    env: Mapping[str, str] | None = None,
    timeout: float = 120.0,
) -> subprocess.CompletedProcess[str]:
    """``python -c code args...`` in this interpreter's environment (or ``env``), its output
    captured as text; the caller checks ``returncode``."""
    return subprocess.run(
        [sys.executable, "-c", code, *args],
        capture_output=True, text=True, cwd=cwd, env=None if env is None else dict(env),
        timeout=timeout,
    )  # fmt: skip
