"""Fixtures of the engine tests: a protocol, the shipped bench, an output path."""

from __future__ import annotations

from pathlib import Path

import pytest

from protocols.bench import BenchFile, load_bench
from protocols.schema import ProtocolFile

from .helpers import PROTOCOL, make_protocol


@pytest.fixture
def protocol() -> ProtocolFile:
    return make_protocol()


@pytest.fixture
def bench() -> BenchFile:
    return load_bench()


@pytest.fixture
def out(tmp_path: Path) -> Path:
    return tmp_path / "run.h5"


@pytest.fixture
def proto_file(tmp_path: Path) -> Path:
    """:data:`helpers.PROTOCOL` as a file."""
    f = tmp_path / "proto.yaml"
    f.write_text(PROTOCOL)
    return f
