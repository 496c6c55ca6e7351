"""The settings-file loader's bounds (issue 16): what stays allowed, and refusals that name the
bound. The command-line view of the same refusals is in tests/bad_inputs."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from protocols.schema import parse_protocol
from protocols.yamlfile import MAX_DEPTH, MAX_NODES, ConfigError, parse_yaml

SMOKE = (Path(__file__).parents[2] / "protocols" / "smoke.yaml").read_text()


def test_an_alias_within_the_bound_still_works() -> None:
    text = SMOKE.replace(
        "  ltr: {f_center: 8.92 kHz, shape: narrowband}",
        "  ltr: &b {f_center: 8.92 kHz, shape: narrowband}\n  rtl: *b",
    ).replace("directions: [ltr]", "directions: both")
    pf = parse_protocol(text, "p.yaml")
    assert pf.protocol.burst["rtl"] == pf.protocol.burst["ltr"]


def test_nesting_at_the_bound_loads_one_more_is_refused() -> None:
    ok = "a: " + "[" * (MAX_DEPTH - 1) + "]" * (MAX_DEPTH - 1)
    assert parse_yaml(ok, "f").data["a"] is not None
    with pytest.raises(ConfigError, match=f"deeper than {MAX_DEPTH} levels"):
        parse_yaml("a: " + "[" * MAX_DEPTH + "]" * MAX_DEPTH, "f")


def test_values_are_counted_with_aliases_expanded() -> None:
    n = MAX_NODES // 10
    base = "x: &a [" + ", ".join(["1"] * n) + "]\n"
    parse_yaml(base + "".join(f"y{i}: *a\n" for i in range(8)), "f")  # 9 n values: allowed
    t0 = time.perf_counter()
    with pytest.raises(ConfigError, match=r"f:\d+: aliases expand to more than"):
        parse_yaml(base + "".join(f"y{i}: *a\n" for i in range(10)), "f")
    assert time.perf_counter() - t0 < 1.0
