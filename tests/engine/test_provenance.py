"""The library versions a run file records (:mod:`daq.store.provenance`): each a distribution
this project installs, read from its metadata. Before, the window's files recorded "PySide6":
"not installed" beside a working PySide6: the project installs ``PySide6-Essentials``."""

from __future__ import annotations

import re
import tomllib
from importlib.metadata import version
from pathlib import Path

from daq.store.provenance import PACKAGES, _packages

ROOT = Path(__file__).resolve().parents[2]


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def test_every_recorded_library_is_one_the_project_installs_and_reads_its_version() -> None:
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    installed = {_norm(re.split(r"[<>=!~;\[ ]", d, maxsplit=1)[0]) for d in deps}
    assert "pyside6-essentials" in installed
    recorded = _packages()
    for name in PACKAGES:
        if _norm(name) in installed:
            assert recorded[name] == version(name), name
    assert not [n for n in PACKAGES if _norm(n) not in installed], PACKAGES
