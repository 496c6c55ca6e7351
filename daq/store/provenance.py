"""What reproduces a run, written into its file at creation (and at every resume).

Root attributes, plain strings and numbers so that plain h5py (or HDFView) reads them:
``software_version``, ``git_commit`` (``"unknown"`` outside a checkout), ``git_dirty``
(1 when the checkout had uncommitted changes, -1 unknown), ``python_version``, ``platform``,
``host``, ``user``, ``command`` (the command line), ``packages_json`` (the versions of the
libraries the data went through). The protocol and bench files as written, each instrument's
identity and settings read back from it, and the simulated world's model parameters are in
``protocol_yaml``, ``bench_yaml`` and ``/snapshot`` (see :meth:`RunEngine` and
:func:`daq.connect.connect_bench`); the instruments as set up for each direction and amplitude
in ``/snapshot/armed``; each resume's own entry in ``resumes_json`` (the layout:
:mod:`protocols.runfile`).
"""

from __future__ import annotations

import getpass
import json
import platform
import socket
import subprocess
import sys
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from protocols.runfile import software_version

__all__ = ["PACKAGES", "git_state", "provenance_attrs"]

#: the libraries whose versions a run file records
PACKAGES = (
    "numpy",
    "scipy",
    "numba",
    "h5py",
    "pydantic",
    "PyYAML",
    "pyvisa",
    "pyvisa-py",
    "pyserial",
    "nidaqmx",
    "PySide6-Essentials",  # the distribution the project installs (import name PySide6)
    "pint",
)

_REPO = Path(__file__).resolve().parents[2]


def git_state(repo: Path = _REPO) -> tuple[str, int]:
    """``(commit, dirty)`` of the checkout this code runs from; ``("unknown", -1)`` when it
    is not a git checkout (an installed wheel) or git is missing."""
    if not (repo / ".git").exists():
        return "unknown", -1
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=repo, capture_output=True, text=True, timeout=5
        )
        status = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=repo,
            capture_output=True,
            text=True,
            timeout=5,
        )
    except (OSError, subprocess.SubprocessError):
        return "unknown", -1
    if commit.returncode != 0 or status.returncode != 0:
        return "unknown", -1
    return commit.stdout.strip(), int(bool(status.stdout.strip()))


def _packages() -> dict[str, str]:
    out = {}
    for name in PACKAGES:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    return out


def provenance_attrs() -> dict[str, Any]:
    """The root attributes listed in the module docstring."""
    commit, dirty = git_state()
    try:
        user = getpass.getuser()
    except (KeyError, OSError):
        user = "unknown"
    return {
        "software_version": software_version(),
        "git_commit": commit,
        "git_dirty": dirty,
        "python_version": sys.version.split()[0],
        "platform": platform.platform(),
        "host": socket.gethostname(),
        "user": user,
        "command": " ".join(sys.argv)[:2000],
        "packages_json": json.dumps(_packages(), sort_keys=True),
    }
