"""Whether a run file may be continued with this bench: the bench comparison of ``--resume``.

A resumed run must be measured on the bench it was started with, or the file mixes two
benches while its stored bench still names the first. :func:`bench_differences` compares the
bench stored in the file with the one given, field by field (cylinder positions, channel map,
amplifier gain and stroke, vibrometer range, DAQ channels and ranges, limits, the simulated
world), and lists every difference in one line each. What cannot change the data is left out:
the bench's name, connection addresses and timeouts, and the simulated bench's injected faults
and speed-up. It is a pure function of two texts, so a pre-flight check can call it before any
instrument is connected.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from protocols.bench import BenchFile, parse_bench
from protocols.yamlfile import ConfigError

__all__ = ["IGNORED_FIELDS", "bench_differences", "chain_differences", "model_differences"]

#: dotted fields that may differ between the start and a resume (they cannot change the data)
IGNORED_FIELDS = (
    "name",
    "generator.resource",
    "generator.timeout",
    "vibrometer.resource",
    "vibrometer.timeout",
    "stage.resource",
    "stage.timeout",
    "cylinder_positions",  # compared as positions (a list and a grid may name the same ones)
    "simulation.faults",
    "simulation.speedup",
)


def _flatten(value: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(value, dict):
        out: dict[str, Any] = {}
        for k, v in value.items():
            out.update(_flatten(v, f"{prefix}{k}."))
        return out
    return {prefix[:-1]: value}


def _ignored(key: str) -> bool:
    return any(key == f or key.startswith(f + ".") for f in IGNORED_FIELDS)


def _show(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, tuple | list):
        return "[" + ", ".join(_show(x) for x in v) + "]"
    return repr(v) if isinstance(v, str) else str(v)


def bench_differences(
    stored_bench_yaml: str, bench: BenchFile, source: str = "the file"
) -> list[str]:
    """Differences between the bench stored in a run file and ``bench``, one line each
    (``"amplifier.gain: 40 in the file, 20 now"``); empty when they match."""
    try:
        stored = parse_bench(stored_bench_yaml, f"{source}:bench_yaml")
    except ConfigError as exc:
        return [f"the bench stored in {source} is unreadable ({str(exc).splitlines()[0]})"]
    a = _flatten(stored.bench.model_dump())
    b = _flatten(bench.bench.model_dump())
    diffs = []
    for key in sorted(set(a) | set(b)):
        if _ignored(key):
            continue
        va, vb = a.get(key), b.get(key)
        if va != vb:
            diffs.append(f"{key}: {_show(va)} in {source}, {_show(vb)} now")
    pa, pb = stored.bench.positions_m(), bench.bench.positions_m()
    if pa.shape != pb.shape:
        diffs.append(f"cylinder positions: {pa.size} in {source}, {pb.size} now")
    elif not np.array_equal(pa, pb):
        k = np.flatnonzero(pa != pb)
        shown = ", ".join(
            f"cylinder {i + 1}: {pa[i] * 1e3:.4g} mm in {source}, {pb[i] * 1e3:.4g} mm now"
            for i in k[:3]
        )
        diffs.append(f"cylinder positions differ at {k.size} cylinder(s) ({shown})")
    return diffs


def chain_differences(
    stored_chain_spec: dict[str, Any] | None, bench: BenchFile, source: str = "the file"
) -> list[str]:
    """Differences between the chain a simulated run was measured on (its snapshot's
    ``simulation_model.chain_spec``) and the chain ``bench`` names now, one line each
    (``"chain diameter: '13.6 mm' in the file, '12 mm' now (chain file mychain.yaml)"``).

    The bench file names its chain by path, so an edited chain file left the bench's text
    unchanged: a resumed run mixed two chains under one ``/chain``. Empty for a lab bench, a
    file that recorded no chain, or the same chain; a chain that cannot be read now is one
    line saying so."""
    if bench.bench.simulation is None or not stored_chain_spec:
        return []
    from daq.chain_info import chain_spec
    from protocols.yamlfile import ConfigError as _ConfigError
    from sim_backend.dem import ChainSpec

    where = f" (chain file {bench.bench.chain})" if bench.bench.chain else ""
    try:
        now = chain_spec(bench).model_dump()
    except _ConfigError as exc:
        return [f"the bench's chain cannot be read now ({str(exc).splitlines()[0]})"]
    try:
        then = ChainSpec.model_validate(stored_chain_spec).model_dump()
    except ValueError:
        return [f"the chain stored in {source} is unreadable"]
    a, b = _flatten(then), _flatten(now)
    return [
        f"chain {key}: {_show(a.get(key))} in {source}, {_show(b.get(key))} now{where}"
        for key in sorted(set(a) | set(b))
        if a.get(key) != b.get(key)
    ]


def model_differences(
    stored_model: dict[str, Any] | None, bench: BenchFile, source: str = "the file"
) -> list[str]:
    """The simulated bench's model version (:func:`sim_backend.dem.versions.model_version`)
    a run was measured with against this software's, one line when they differ or the file
    did not record it (made before 2026-11-28): points of two DEM kernels would mix in one
    file. Empty for a lab bench."""
    if bench.bench.simulation is None or stored_model is None:
        return []
    from sim_backend.dem.versions import model_version

    now = model_version()
    then = stored_model.get("model_version")
    if then == now:
        return []
    if not then:
        return [
            f"simulated bench model: not recorded in {source} (made before run files recorded "
            f"it), {now!r} now"
        ]
    return [f"simulated bench model: {then!r} in {source}, {now!r} now"]
