"""Hypothesis over the protocol and bench schemas (issue 16): mutated files through the real
``run_protocol`` entry point, with instrument connections forbidden.

Mutations that no field may accept (an unknown key, a wrong unit, a mapping where a value goes,
a value that is not finite, a huge magnitude, bytes that are not UTF-8) must be refused like the
cases of cases.py: exit 2, one line naming the file, no traceback, nothing written, no
instrument, under 2 s. Any other mutation (zero, negative, a missing key, an arbitrary number or
text) may be valid: then ``--dry-run`` accepts it and the run gets as far as connecting; if not,
it is refused in the same way, and ``--dry-run`` agrees with the run.
"""

from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from .cases import SIM_BENCH, SMOKE, Case
from .runner import Outcome, check_refused, run_case

TEMPLATES = {"proto.yaml": yaml.safe_load(SMOKE), "bench.yaml": yaml.safe_load(SIM_BENCH)}
ARGV = ("run_protocol", "proto.yaml", "--bench", "bench.yaml", "--out", "run.h5")
QUANTITY = re.compile(r"^\s*[-+]?[\d.]+(?:e[-+]?\d+)?\s*([A-Za-z/%]+.*)$")
#: mappings whose keys are free (no unknown key there): the simulated faults
FREE_MAPPINGS = {("simulation", "faults")}
#: examples per test: a few seconds in CI, the same examples every run; BIAFC_FUZZ_EXAMPLES=2000
#: searches longer with fresh random examples
_DEEP = int(os.environ.get("BIAFC_FUZZ_EXAMPLES", "0"))
FUZZ = settings(
    max_examples=_DEEP or 60,
    deadline=None,  # the runner asserts its own 2 s bound; the first example imports more
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    derandomize=not _DEEP,
    database=None,
)

Path_ = tuple[str | int, ...]


def _nodes(data: Any, path: Path_ = ()) -> list[tuple[Path_, Any]]:
    out: list[tuple[Path_, Any]] = [(path, data)]
    if isinstance(data, dict):
        for k, v in data.items():
            out += _nodes(v, (*path, k))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            out += _nodes(v, (*path, i))
    return out


def _leaves(data: Any) -> list[tuple[Path_, Any]]:
    return [(p, v) for p, v in _nodes(data) if p and not isinstance(v, dict | list)]


def _mappings(data: Any) -> list[Path_]:
    return [p for p, v in _nodes(data) if isinstance(v, dict) and p not in FREE_MAPPINGS]


def _copy(data: Any) -> Any:
    return yaml.safe_load(yaml.safe_dump(data))


def _set(data: Any, path: Path_, value: Any) -> Any:
    out = _copy(data)
    target = out
    for p in path[:-1]:
        target = target[p]
    target[path[-1]] = value
    return out


def _delete(data: Any, path: Path_) -> Any:
    out = _copy(data)
    target = out
    for p in path[:-1]:
        target = target[p]
    del target[path[-1]]
    return out


def _dump(data: Any) -> bytes:
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True).encode()


@st.composite
def must_refuse(draw: st.DrawFn) -> tuple[str, str, bytes]:
    """(file, what was done, its new bytes): a mutation no field may accept."""
    name = draw(st.sampled_from(sorted(TEMPLATES)))
    data = TEMPLATES[name]
    leaves = _leaves(data)
    quantities = [(p, v) for p, v in leaves if isinstance(v, str) and QUANTITY.match(v)]
    numbers = [(p, v) for p, v in leaves if isinstance(v, int | float) and not isinstance(v, bool)]
    kind = draw(st.sampled_from(["unknown", "unit", "mapping", "nonfinite", "huge", "bytes"]))
    event(f"{name}: {kind}")
    if kind == "unknown":
        where = draw(st.sampled_from(_mappings(data)))
        key = "zz_" + draw(st.text("abcdefghijklmnopqrstuvwxyz_", min_size=1, max_size=8))
        return name, f"unknown key {key} in {where}", _dump(_set(data, (*where, key), 1))
    if kind == "unit":
        path, value = draw(st.sampled_from(quantities))
        unit = draw(st.sampled_from(["kg", "mol", "cd", "furlong"]))
        number = QUANTITY.sub("", value) or value.split()[0]
        new = re.sub(r"[A-Za-z/%].*$", unit, value.strip())
        del number
        return name, f"{path}: {new!r}", _dump(_set(data, path, new))
    if kind == "mapping":
        path, _ = draw(st.sampled_from(leaves))
        return name, f"{path}: a mapping", _dump(_set(data, path, {"a": 1}))
    if kind in ("nonfinite", "huge"):
        path, value = draw(st.sampled_from(quantities + numbers))
        if kind == "nonfinite":
            x = draw(st.sampled_from(["nan", "inf", "-inf"]))
        else:
            x = draw(st.sampled_from(["1e300", "-1e300", "1e30"]))
        if isinstance(value, str):
            m = QUANTITY.match(value)
            assert m is not None
            new: Any = f"{x} {m.group(1)}"
        else:
            new = float(x)
        return name, f"{path}: {new!r}", _dump(_set(data, path, new))
    text = _dump(data)
    at = draw(st.integers(0, len(text)))
    junk = draw(st.binary(min_size=1, max_size=16).map(lambda b: b"\xff" + b))
    return name, f"bytes {junk!r} at {at}", text[:at] + junk + text[at:]


@st.composite
def any_mutation(draw: st.DrawFn) -> tuple[str, str, bytes]:
    """(file, what was done, its new bytes): a mutation that may or may not be valid."""
    name = draw(st.sampled_from(sorted(TEMPLATES)))
    data = TEMPLATES[name]
    path, _ = draw(st.sampled_from(_nodes(data)[1:]))
    kind = draw(st.sampled_from(["delete", "zero", "negative", "number", "text", "bool"]))
    event(f"{name}: {kind}")
    if kind == "delete":
        return name, f"{path} deleted", _dump(_delete(data, path))
    value: Any = {
        "zero": 0,
        "negative": draw(st.sampled_from([-1, "-1 ms", "-5 V", "-2 mm", "-1 um"])),
        "number": draw(st.one_of(st.integers(-(10**12), 10**12), st.floats(allow_nan=False))),
        "text": draw(st.text(max_size=20)),
        "bool": draw(st.booleans()),
    }[kind]
    return name, f"{path}: {value!r}", _dump(_set(data, path, value))


def _files(name: str, content: bytes) -> dict[str, bytes]:
    files = {n: _dump(d) for n, d in TEMPLATES.items()}
    files[name] = content
    return files


def _run(case: Case) -> Outcome:
    with tempfile.TemporaryDirectory() as tmp, pytest.MonkeyPatch.context() as mp:
        return run_case(case, Path(tmp), {}, mp)


def test_the_templates_are_valid() -> None:
    """The mutations start from a request --dry-run accepts."""
    case = Case(
        "valid", "", (*ARGV, "--dry-run"), (), _files("proto.yaml", _dump(TEMPLATES["proto.yaml"]))
    )
    out = _run(case)
    assert out.code == 0 and not out.escaped, out.stderr


@FUZZ
@given(must_refuse())
def test_what_no_field_accepts_is_refused_in_one_line(mutation: tuple[str, str, bytes]) -> None:
    name, what, content = mutation
    case = Case("fuzz", what, ARGV, (name,), _files(name, content))
    check_refused(case, _run(case))


@FUZZ
@given(any_mutation())
def test_any_mutation_is_refused_in_one_line_or_runs(mutation: tuple[str, str, bytes]) -> None:
    name, what, content = mutation
    dry = _run(Case("fuzz", what, (*ARGV, "--dry-run"), (), _files(name, content)))
    case = Case("fuzz", what, ARGV, (name,), _files(name, content))
    out = _run(case)
    event("accepted" if dry.code == 0 else "refused")
    if dry.code == 0 and not dry.escaped:
        assert out.connected, f"--dry-run accepts {what} but the run did not get to connecting"
        return
    check_refused(Case("fuzz", what, (*ARGV, "--dry-run"), (), _files(name, content)), dry)
    check_refused(case, out)
