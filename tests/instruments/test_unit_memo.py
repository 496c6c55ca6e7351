"""Parsed units remembered across processes (instruments/unit_memo.py): pint, whose import and
registry took 0.15-0.23 s of every command reading a bench file or a protocol, answers once per
unit on a machine; the memo gives its answers back unchanged, and a damaged, foreign or
unwritable memo costs only the speed-up (issue 18, no hidden seconds)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from instruments import units
from instruments.unit_memo import MAX_ENTRIES, UnitMemo
from tests.fresh_process import python_c

ROOT = Path(__file__).resolve().parents[2]

#: units a lab types, right and wrong, each with the dimensions asked of it
ASKED = [
    (unit, dimension)
    for unit in ("kHz", "Hz", "nm", "um", "µm", "micron", "mm/s/V", "um/V", "MS/s", "Vpp", "mVpk",
                 "V", "N", "kg/m^3", "g/cm3", "deg", "GPa", "ms", "furlong", "m*s", "2**2**2")
    for dimension in ("frequency", "length", "velocity_per_volt", "peak_to_peak_voltage",
                      "density", "angle", "time")
]  # fmt: skip


def test_the_memo_gives_back_pints_answers_exactly(tmp_path: Path) -> None:
    first = UnitMemo(tmp_path, ["key"])
    answers = {}
    for unit, dimension in ASKED:
        answers[unit, dimension] = units._pint_factor(unit, dimension)
        first.remember(unit, dimension, answers[unit, dimension])
    again = UnitMemo(tmp_path, ["key"])  # a new process's memo: read from the file
    for (unit, dimension), answer in answers.items():
        assert again.recall(unit, dimension) == answer, (unit, dimension)
    assert any(a[0] is None for a in answers.values()) and any(a[0] for a in answers.values())


def test_two_processes_remembering_in_turn_keep_both_answers(tmp_path: Path) -> None:
    """Each memo read the file before the other wrote; each write merges into the file as it is
    now (``instruments.cache_entries``), so neither answer is lost (the memo wrote its own view
    over the file before, and the first answer was gone)."""
    first, second = UnitMemo(tmp_path, ["key"]), UnitMemo(tmp_path, ["key"])
    assert first.recall("nm", "length") is None and second.recall("kHz", "frequency") is None
    first.remember("nm", "length", (1e-9, ""))
    second.remember("kHz", "frequency", (1000.0, ""))
    again = UnitMemo(tmp_path, ["key"])
    assert again.recall("nm", "length") == (1e-9, "")
    assert again.recall("kHz", "frequency") == (1000.0, "")


def test_another_key_is_another_memo(tmp_path: Path) -> None:
    UnitMemo(tmp_path, ["units.py v1", "pint a"]).remember("nm", "length", (1e-9, ""))
    assert UnitMemo(tmp_path, ["units.py v2", "pint a"]).recall("nm", "length") is None
    assert UnitMemo(tmp_path, ["units.py v1", "pint b"]).recall("nm", "length") is None
    assert UnitMemo(tmp_path, ["units.py v1", "pint a"]).recall("nm", "length") == (1e-9, "")


@pytest.mark.parametrize(
    "content",
    [b"\x00\xff not json", b"[1, 2]", b'{"nm\\u0000length": [NaN, ""]}',
     b'{"nm\\u0000length": [true, ""]}', b'{"nm\\u0000length": ["1e-9", ""]}',
     b'{"nm\\u0000length": [1e-9]}', b'{"nm\\u0000length": 1e-9}'],
)  # fmt: skip
def test_a_damaged_memo_is_an_empty_one_and_is_written_again(
    tmp_path: Path, content: bytes
) -> None:
    memo = UnitMemo(tmp_path, ["key"])
    memo.path.write_bytes(content)
    assert memo.recall("nm", "length") is None
    memo.remember("nm", "length", (1e-9, ""))
    assert json.loads(memo.path.read_text(encoding="utf-8")) == {"nm\u0000length": [1e-9, ""]}


def test_an_unwritable_memo_path_costs_only_the_speed_up(tmp_path: Path) -> None:
    """The cache folder's place is taken by a file, so nothing can be written (a read-only
    folder does the same, but not to root, who runs CI here)."""
    blocker = tmp_path / "cache"
    blocker.write_text("a file, not a folder")
    memo = UnitMemo(blocker, ["key"])
    memo.remember("nm", "length", (1e-9, ""))  # no error
    assert memo.recall("nm", "length") == (1e-9, "")  # still kept in this process


def test_the_memo_stops_growing_at_its_bound(tmp_path: Path) -> None:
    memo = UnitMemo(tmp_path, ["key"])
    for j in range(MAX_ENTRIES + 5):
        memo._load()[f"u{j}\0length"] = (1.0, "")  # filled without writing each time
    memo.remember("nm", "length", (1e-9, ""))
    assert memo.recall("nm", "length") is None


def test_a_second_process_reads_the_shipped_files_without_pint(tmp_path: Path) -> None:
    """The shipped protocols and bench in a fresh process: the first one on an empty cache
    folder imports pint, the next does not (each did before the memo), with the same values."""
    code = (
        "import json, sys\n"
        "from protocols.bench import load_bench\n"
        "from protocols.schema import load_protocol\n"
        "values = [load_protocol(n).protocol.model_dump() for n in "
        "('smoke', 'ltr_highamp', 'rtl_highamp', 'linear_lowamp', 'biafc_sweep')]\n"
        "values.append(load_bench(None).bench.model_dump())\n"
        "print(json.dumps(['pint' in sys.modules, values], default=str))\n"
    )
    env = dict(os.environ, BIAFC_CACHE_DIR=str(tmp_path))
    runs = []
    for _ in range(2):
        out = python_c(code, cwd=ROOT, env=env)
        assert out.returncode == 0, out.stderr
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    (pint_first, values_first), (pint_second, values_second) = runs
    assert pint_first and not pint_second
    assert values_second == values_first
    assert list(tmp_path.glob("units-*.json"))
