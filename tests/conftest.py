"""Shared pytest configuration: the ``hardware`` marker and offscreen Qt."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
os.environ.setdefault("MPLBACKEND", "Agg")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--hardware",
        action="store_true",
        default=False,
        help="run tests that need the real bench (instruments connected)",
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--hardware"):
        return
    skip = pytest.mark.skip(reason="needs the real bench: run with --hardware on the lab PC")
    for item in items:
        if "hardware" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(autouse=True)
def _no_file_left_open_across_tests(monkeypatch: pytest.MonkeyPatch) -> None:
    """A test whose writer gave up on its file (a faked full disk) marks this process as one
    that must end without HDF5's clean-up (:mod:`protocols.left_open`); the next test's
    in-process CLI would then end pytest itself. Each test starts with none."""
    from protocols import left_open

    monkeypatch.setattr(left_open, "_LEFT", [])


@pytest.fixture(autouse=True)
def _no_terminal_log_handler_across_tests() -> Iterator[None]:
    """An in-process CLI installs ``biafc``'s terminal handler on the ``sys.stderr`` of its
    test (pytest's capture, closed after it); a later test's log record then failed with
    "--- Logging error --- ValueError: I/O operation on closed file". Each test leaves none."""
    import logging

    yield
    logger = logging.getLogger("biafc")
    for h in list(logger.handlers):
        if getattr(h, "_biafc_terminal", False):
            logger.removeHandler(h)
