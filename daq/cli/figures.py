"""``biafc figures``: the paper's figures and a summary from a run file, or the alpha sweep.

    biafc figures RUN.h5 [--out DIR]
    biafc figures --alpha-sweep [--alphas 0.1,0.2] [--amplitude 2um] [--duration 8ms]
                  [--cycles 10] [--out DIR]

Writes PNG and PDF figures and ``summary.json`` into DIR (default: ``<RUN>_figures`` beside the
run file, or ``alpha_sweep_figures`` for the sweep) and prints the summary.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from daq.cli.biafc import CliError

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_file", nargs="?", type=Path, help="run file (HDF5) to draw from")
    parser.add_argument("--out", type=Path, default=None, help="folder for the figures")
    parser.add_argument(
        "--alpha-sweep",
        action="store_true",
        help="run the asymmetry sweep on the DEM (paper Fig. 4b-c) instead of reading a file",
    )
    parser.add_argument(
        "--alphas",
        default=None,
        help="comma-separated asymmetry factors for --alpha-sweep (dimensionless)",
    )
    parser.add_argument(
        "--amplitude",
        default=None,
        help="drive amplitude for --alpha-sweep, with its unit (e.g. 2um or 12N)",
    )
    parser.add_argument(
        "--duration", default=None, help="simulated time per run for --alpha-sweep (e.g. 8ms)"
    )
    parser.add_argument(
        "--cycles", type=float, default=None, help="burst length in cycles for --alpha-sweep"
    )


def _alpha_sweep(args: argparse.Namespace) -> int:
    from instruments.units import parse_quantity

    try:
        from analysis import alpha_sweep
    except ImportError as exc:  # the DEM is not installed in this tree
        raise CliError(f"the alpha sweep needs the DEM (sim_backend.dem): {exc}") from exc
    kwargs: dict[str, object] = {}
    if args.alphas is not None:
        try:
            alphas = [float(a) for a in str(args.alphas).split(",") if a.strip()]
        except ValueError as exc:
            raise CliError(f"--alphas: expected numbers separated by commas ({exc})") from exc
        if not alphas or any(a < 0 for a in alphas):
            raise CliError("--alphas: give at least one asymmetry factor, each >= 0")
        kwargs["alphas"] = alphas
    if args.amplitude is not None:
        try:
            kwargs["amplitude"] = alpha_sweep.parse_amplitude(str(args.amplitude))
        except ValueError as exc:
            raise CliError(f"--amplitude: {exc}") from exc
    if args.duration is not None:
        try:
            kwargs["duration_s"] = parse_quantity(str(args.duration), "time", field="--duration")
        except ValueError as exc:
            raise CliError(f"--duration: {exc}") from exc
    if args.cycles is not None:
        if not args.cycles > 0:
            raise CliError("--cycles: must be > 0")
        kwargs["cycles"] = float(args.cycles)
    out = args.out or Path("alpha_sweep_figures")
    try:
        result = alpha_sweep.run_alpha_sweep(**kwargs)  # type: ignore[arg-type]
    except ValueError as exc:
        raise CliError(str(exc)) from exc
    paths = alpha_sweep.write_alpha_sweep(result, out)
    print(alpha_sweep.format_alpha_sweep(result))
    for p in paths:
        print(f"written {p}")
    return 0


def run(args: argparse.Namespace) -> int:
    if args.alpha_sweep:
        if args.run_file is not None:
            raise CliError("give either a run file or --alpha-sweep, not both")
        return _alpha_sweep(args)
    if args.run_file is None:
        raise CliError("give a run file (biafc figures RUN.h5) or --alpha-sweep")
    for name in ("alphas", "amplitude", "duration", "cycles"):
        if getattr(args, name) is not None:
            raise CliError(f"--{name} applies only with --alpha-sweep")
    from analysis.report import write_figures
    from daq.cli.run_input import read_run_file

    path: Path = args.run_file
    data = read_run_file(path)
    out = args.out or path.with_name(f"{path.stem}_figures")
    try:
        report = write_figures(data, out)
    except ValueError as exc:
        raise CliError(f"{path}: {exc}") from exc
    print(report.summary_text)
    for name, paths in report.figures.items():
        print(f"written {name}: {', '.join(str(p) for p in paths)}")
    for name, why in report.skipped.items():
        print(f"skipped {name}: {why}")
    print(f"written {report.summary_path}")
    return 0
