"""``biafc repair RUN.h5 [RUN.h5 ...]``: make run files and study outputs (``biafc study``) left
by a killed writer readable by any
HDF5 reader, without losing a point (:mod:`daq.store.repair`). Exit 0 when every file opens
with plain h5py afterwards; 2 when one is refused (not a run file, written by a live process);
1 when a repair failed on the way (HDF5 could not write the file, or damage remained after
clearing it): one line naming the file, never a traceback."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "files", type=Path, nargs="+", metavar="RUN.h5", help="run file(s) or study output(s)"
    )


def run(args: argparse.Namespace) -> int:
    from daq.store import StoreError
    from daq.store.repair import repair_run

    code = 0
    for path in args.files:
        try:
            print(f"repaired {repair_run(path).line()}")
        except StoreError as exc:
            print(f"biafc repair: refused: {exc}", file=sys.stderr)
            code = 2
        except Exception as exc:  # HDF5 or damage found where none was expected: one line
            first = str(exc).splitlines()[0] if str(exc) else ""
            print(f"biafc repair: failed: {path}: {type(exc).__name__}: {first}", file=sys.stderr)
            code = max(code, 1)
    return code
