"""``biafc gui [--bench BENCH.yaml] [--protocol PROTOCOL.yaml] [--run RUN.h5] [--connect]``:
the bench window (same as ``biafc-gui``)."""

from __future__ import annotations

import argparse

from daq.cli.biafc import CliError

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from daq.gui.app import add_arguments as gui_arguments

    gui_arguments(parser)


def run(args: argparse.Namespace) -> int:
    from daq.gui.app import check_paths, display_problem, run_window

    err = check_paths(args) or display_problem()
    if err is not None:
        raise CliError(err)
    return run_window(args)
