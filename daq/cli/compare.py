"""``biafc compare RUN.h5 [--chain CHAIN.yaml] [--piezo-stroke 0.04um/V] [--out DIR]``.

Runs the model on exactly what the run did (bursts, amplitudes through the bench's amplifier
gain and piezo stroke, cylinders, directions, record length, sample rate, vibrometer range:
:mod:`analysis.model_run`), prints the per-cylinder residual table and the figure of merit, and
writes the measured and predicted figures side by side into DIR (default ``<RUN>_compare``
beside the run file). Without ``--chain`` the model is the chain recorded in the file's
``/chain`` (lengths, diameter, preload; the rest from the default chain). ``--piezo-stroke``
replaces the bench's stroke (e.g. the one ``biafc calibrate`` fitted). ``--linear`` uses the
linear-response solver instead of the DEM (fast; right only at small amplitude).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from daq.cli.biafc import CliError
from daq.cli.out_check import can_write_folder
from daq.cli.written import print_written

__all__ = ["add_arguments", "parse_stroke", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_file", type=Path, help="run file (HDF5), measured or simulated")
    parser.add_argument("--chain", type=Path, help="chain file (YAML); default: the file's chain")
    parser.add_argument(
        "--piezo-stroke",
        help="piezo stroke per volt with unit (e.g. '0.04 um/V'); default: the bench's",
    )
    parser.add_argument("--out", type=Path, help="folder for the figures and the table")
    parser.add_argument(
        "--linear", action="store_true", help="linear-response model instead of the DEM"
    )


def parse_stroke(text: str) -> float:
    """``'0.04 um/V'`` -> 4e-8 (m/V); raises :class:`CliError`."""
    from instruments.units import UnitError, parse_quantity

    try:
        value = parse_quantity(text, "length_per_volt", field="--piezo-stroke")
    except UnitError as exc:
        raise CliError(str(exc)) from None
    if not value > 0:
        raise CliError(f"--piezo-stroke {text!r}: must be > 0")
    return value


def run(args: argparse.Namespace) -> int:
    from analysis.compare_report import compare_run
    from daq.cli.run_input import read_run_and_chain

    path: Path = args.run_file
    data, spec = read_run_and_chain(path, args.chain)
    stroke = parse_stroke(args.piezo_stroke) if args.piezo_stroke else None
    out = args.out or path.with_name(f"{path.stem}_compare")
    can_write_folder(out, "--out")  # before the model runs, not after

    # the table first, then each figure as it is saved: the figures take 5.5 of 7.5 s on a
    # biafc_sweep run, and everything had been printed at once at its end
    def text(table: str) -> None:
        print(table, flush=True)

    try:
        report = compare_run(
            data,
            out,
            chain_spec=spec,
            piezo_stroke_m_per_V=stroke,
            solver="linear" if args.linear else "dem",
            on_text=text,
            on_written=print_written,
        )
    except ValueError as exc:
        raise CliError(f"{path}: {exc}") from exc
    for name, why in report.not_drawn.items():
        print(f"not drawn {name}: {why}")
    print(f"written {report.csv_path}")
    print(f"written {report.json_path}")
    return 0
