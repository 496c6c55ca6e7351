"""docs/files.md names every field the protocol and bench schemas accept, and every fault of
the simulated bench: a field added to a schema without a line there fails here (a second
reader found the protocol file described nowhere, and a documented key the schema refused)."""

from __future__ import annotations

import typing
from pathlib import Path

from pydantic import BaseModel

from protocols.bench import BenchSpec
from protocols.schema import Protocol
from sim_backend.simbench.faults import FAULT_NAMES

DOC = (Path(__file__).resolve().parents[2] / "docs" / "files.md").read_text(encoding="utf-8")


def _models(annotation: object) -> list[type[BaseModel]]:
    found: list[type[BaseModel]] = []
    for a in (annotation, *typing.get_args(annotation)):
        if isinstance(a, type) and issubclass(a, BaseModel):
            found.append(a)
        found += [b for b in typing.get_args(a) if isinstance(b, type) and issubclass(b, BaseModel)]
    return found


def field_paths(model: type[BaseModel], prefix: str = "") -> list[str]:
    """Every field of ``model`` as a dotted path, nested models included."""
    out: list[str] = []
    for name, info in model.model_fields.items():
        path = prefix + name
        out.append(path)
        for sub in _models(info.annotation):
            out += field_paths(sub, path + ".")
    return out


def test_every_protocol_and_bench_field_is_on_the_page() -> None:
    paths = field_paths(Protocol) + field_paths(BenchSpec)
    assert "vibrometer.level_full_scale" in paths and "acquisition.pre_trigger" in paths
    groups = {p.rsplit(".", 1)[0] for p in paths if "." in p}  # named through their fields
    missing = [p for p in paths if f"`{p}`" not in DOC and p not in groups]
    assert not missing, f"docs/files.md does not name {missing}"


def test_every_fault_is_on_the_page() -> None:
    missing = [name for name in FAULT_NAMES if f"`{name}`" not in DOC]
    assert not missing and "`after_acquisitions`" in DOC, missing


def test_every_field_the_page_names_is_accepted() -> None:
    """The other way: a key the page tells the lab to write must be one the schema takes
    (before, docs/instruments.md named ``level_full_scale``, which the bench file refused)."""
    import re

    paths = set(field_paths(Protocol) + field_paths(BenchSpec))
    named = [
        name
        for line in DOC.splitlines()
        if line.startswith("| `")
        for name in re.findall(r"`([a-z_.]+)`", line.split("|")[1])
    ]
    assert len(named) >= 80
    assert not [n for n in named if n not in paths], [n for n in named if n not in paths]
