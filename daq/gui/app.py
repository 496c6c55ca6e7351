"""``biafc-gui [--bench BENCH.yaml] [--protocol PROTOCOL.yaml] [--run RUN.h5] [--connect]``:
the bench window."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

__all__ = ["add_arguments", "main", "run_window"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--bench", type=Path, default=None, help="bench file (default: the simulated bench)"
    )
    parser.add_argument("--protocol", type=Path, default=None, help="protocol file to open")
    parser.add_argument("--run", type=Path, default=None, help="run file to browse")
    parser.add_argument("--connect", action="store_true", help="connect the bench at start")


def check_paths(args: argparse.Namespace) -> str | None:
    """The first missing file named on the command line, as a one-line message, or None."""
    for flag in ("bench", "protocol", "run"):
        p = getattr(args, flag)
        if p is not None and not Path(p).is_file():
            return f"--{flag}: {p} does not exist"
    return None


def run_window(args: argparse.Namespace) -> int:
    """Open the window and run the Qt event loop; returns the exit code."""
    from PySide6.QtWidgets import QApplication

    from daq.gui.main_window import MainWindow

    app = QApplication.instance() or QApplication(sys.argv[:1])
    app.setApplicationName("biafc-lab")
    win = MainWindow(args.bench, args.protocol)
    if args.run is not None:
        win.open_run_file(args.run)
    if args.connect:
        win.connect_bench()
    win.show()
    return int(app.exec())


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="biafc-gui", description="The biafc-lab bench window.")
    add_arguments(parser)
    args = parser.parse_args(argv)
    err = check_paths(args)
    if err is not None:
        print(f"biafc-gui: error: {err}", file=sys.stderr)
        return 2
    return run_window(args)


if __name__ == "__main__":
    sys.exit(main())
