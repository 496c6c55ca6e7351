"""The console scripts end with a quick interpreter shutdown (``daq.cli.shutdown.settle``):
garbage collected while everything exists, the survivors frozen for the shutdown's own
collections, which walked numba's, pint's and scipy's objects for 0.25-0.4 s after every
``run_protocol`` and ``biafc`` command (issue 18, no hidden seconds)."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pytest

from tests.fresh_process import python_c

ROOT = Path(__file__).resolve().parents[2]

#: the module whose ``main`` each console script runs (patched in the child: the test is about
#: what happens around it)
MAINS = {"run_protocol": "daq.cli.run_protocol", "biafc": "daq.cli.biafc"}

_CHILD = """
import gc, importlib, json, sys
entry_module, entry_name, main_module, marker = sys.argv[1:5]

class Held:
    def __del__(self):
        with open(marker, "w") as f:
            f.write("finalised")

def main(*args, **kwargs):
    a, b = Held(), Held()
    a.other, b.other = b, a  # cyclic garbage once main returns: only a collection frees it
    return 0

importlib.import_module(main_module).main = main
code = getattr(importlib.import_module(entry_module), entry_name)()
print(json.dumps({"code": code, "frozen": gc.get_freeze_count()}))
"""


def _scripts() -> dict[str, str]:
    with open(ROOT / "pyproject.toml", "rb") as f:
        return dict(tomllib.load(f)["project"]["scripts"])


def test_every_console_script_but_the_window_is_covered() -> None:
    scripts = _scripts()
    assert set(scripts) - {"biafc-gui"} == set(MAINS)


@pytest.mark.parametrize("script", sorted(MAINS))
def test_a_console_script_settles_the_collector_and_runs_every_finaliser(
    script: str, tmp_path: Path
) -> None:
    """The entry point the installed script calls (read from pyproject.toml) returns main's
    status with the live objects frozen (``gc.get_freeze_count() > 0``; 0 before, when
    ``biafc`` called ``main`` directly and ``run_protocol`` did not settle), and the garbage
    that ``main`` left in a reference cycle was finalised before the process ended."""
    module, name = _scripts()[script].split(":")
    marker = tmp_path / "finalised.txt"
    out = python_c(_CHILD, module, name, MAINS[script], str(marker), cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["code"] == 0
    assert result["frozen"] > 1000, result  # the program's objects, not a handful
    assert marker.read_text() == "finalised"


def test_python_dash_m_daq_settles_too(tmp_path: Path) -> None:
    """``python -m daq`` (the same commands as ``biafc``) ends the same way."""
    code = (
        "import gc, runpy, sys\n"
        "import daq.cli.biafc as b\n"
        "b.main = lambda *a, **k: 0\n"
        "sys.argv = ['daq']\n"
        "try:\n"
        "    runpy.run_module('daq', run_name='__main__')\n"
        "except SystemExit as exc:\n"
        "    print(exc.code, gc.get_freeze_count())\n"
    )
    out = python_c(code, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    status, frozen = out.stdout.split()
    assert status == "0" and int(frozen) > 1000
