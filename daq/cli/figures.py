"""``biafc figures``: the paper's figures and a summary from a run file, the figures of a design
study, or the alpha sweep.

    biafc figures RUN.h5 [--out DIR]
    biafc figures STUDY.h5 [--x diameter --y preload] [--metric asymmetry_ratio]
                  [--fix amplitude=2um] [--reduce mean|median|max|min]
                  [--target asymmetry_ratio | min:error_estimate_ltr] [--top 10]
                  [--where transmission_ltr>0.01] [--out DIR]
    biafc figures --alpha-sweep [--alphas 0.1,0.2] [--amplitude 2um] [--duration 30ms]
                  [--cycles 21] [--linear-reference 10nm|none] [--out DIR]

A study output (``biafc study``) gives a phase diagram per metric (``map_<metric>``: the metric
over two parameters, the others fixed with ``--fix`` or marginalised with ``--reduce``), the
paper's Fig. 4 (``alpha_sweep``) for a study over ``alpha`` that recorded its spectra, and the
ranked table of the best designs for ``--target`` (``best_designs.txt``).

Writes PNG and PDF figures and ``summary.json`` into DIR (default: ``<RUN>_figures`` beside the
run file, or ``runs/alpha_sweep_figures`` for the sweep) and prints the summary.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from daq.cli.biafc import CliError
from daq.cli.out_check import can_write_folder
from daq.cli.written import print_written

if TYPE_CHECKING:
    from protocols.studyfile import StudyData

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
        "--duration",
        default=None,
        help="simulated time per run for --alpha-sweep (default 30ms, the paper's window; the "
        "default sweep takes about 2 s with the figures)",
    )
    parser.add_argument(
        "--cycles",
        type=float,
        default=None,
        help="burst length in cycles for --alpha-sweep (default 21, the narrowband burst)",
    )
    parser.add_argument(
        "--linear-reference",
        default=None,
        metavar="AMP|none",
        help="--alpha-sweep also runs every alpha at this small drive (default 10nm) and tells "
        "conversion from the far cylinder's filtering by it; 'none' for no reference",
    )
    study = parser.add_argument_group("design studies (a biafc study output)")
    study.add_argument("--x", default=None, help="parameter along x (default: the first varied)")
    study.add_argument("--y", default=None, help="parameter along y (default: the second)")
    study.add_argument(
        "--metric", action="append", default=None, help="metric to map (repeatable; default all)"
    )
    study.add_argument(
        "--fix",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="hold a parameter at a value, with its unit (amplitude=2um, preload=5N)",
    )
    study.add_argument(
        "--reduce",
        default=None,
        help="over the other parameters: mean (default), median, max, min; given, the drive "
        "amplitude is reduced too (by default the maps are drawn at the largest amplitude)",
    )
    study.add_argument(
        "--target", default=None, help="metric to rank designs by (min:NAME for the smallest)"
    )
    study.add_argument("--top", type=int, default=10, help="designs in the ranked table")
    study.add_argument(
        "--where",
        action="append",
        default=[],
        metavar="METRIC>VALUE",
        help="rank only cells meeting it (transmission_ltr>0.01; SI; repeatable)",
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
    if args.linear_reference is not None:
        if str(args.linear_reference).strip().lower() == "none":
            kwargs["reference_amplitude"] = None
        else:
            try:
                ref = alpha_sweep.parse_amplitude(str(args.linear_reference))
            except ValueError as exc:
                raise CliError(f"--linear-reference: {exc}") from exc
            if not ref[1] > 0:
                raise CliError("--linear-reference: must be > 0 (or 'none')")
            kwargs["reference_amplitude"] = ref
    out = args.out or Path("runs") / "alpha_sweep_figures"  # runs/: where results go, ignored
    can_write_folder(out, "--out")
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
    for name in ("alphas", "amplitude", "duration", "cycles", "linear_reference"):
        if getattr(args, name) is not None:
            raise CliError(f"--{name.replace('_', '-')} applies only with --alpha-sweep")
    path: Path = args.run_file
    from daq.cli.run_input import read_run_or_study
    from protocols.runfile import RunData
    from protocols.studyformat import StudyFileError

    try:  # one open of the file, before matplotlib is imported: a refusal comes at once
        data = read_run_or_study(path)
    except StudyFileError as exc:
        raise CliError(str(exc)) from None
    except CliError:
        _refuse_study_options(args)  # named first, as for any file that is no study output
        raise
    if not isinstance(data, RunData):  # a study output (its schema imported only for one)
        return _study_figures(args, path, data)
    _refuse_study_options(args)
    from analysis.report import write_figures

    out = args.out or path.with_name(f"{path.stem}_figures")
    can_write_folder(out, "--out")

    # the summary first, then each figure as it is saved: drawing takes 5 of 5.4 s on a
    # biafc_sweep run, and everything had been printed at once at its end
    def summary(text: str) -> None:
        print(text, flush=True)

    try:
        report = write_figures(data, out, on_summary=summary, on_written=print_written)
    except ValueError as exc:
        raise CliError(f"{path}: {exc}") from exc
    print(f"written {report.summary_path}")
    for name, why in report.skipped.items():  # known once drawn: after the figures
        print(f"left out {name}: {why}")
    return 0


def _refuse_study_options(args: argparse.Namespace) -> None:
    """Refuse the options that apply only to a study output."""
    for name in ("x", "y", "metric", "target"):
        if getattr(args, name) is not None:
            raise CliError(f"--{name} applies only to a study output")
    if args.fix or args.where:
        raise CliError("--fix and --where apply only to a study output")


def _parse_fix(items: list[str], amplitude_kind: str) -> dict[str, float]:
    from instruments.units import UnitError, parse_quantity
    from protocols.study import PARAMETERS

    out: dict[str, float] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name or not text.strip():
            raise CliError(f"--fix {item!r}: write NAME=VALUE, e.g. amplitude=2um")
        if name == "amplitude":
            dim = "length" if amplitude_kind == "displacement" else "force"
        elif name in PARAMETERS:
            dim = PARAMETERS[name].dimension
        else:
            raise CliError(f"--fix {name}: not a study parameter")
        try:
            out[name] = (
                float(text) if dim == "dimensionless" else parse_quantity(text, dim, field=name)
            )
        except (UnitError, ValueError) as exc:
            raise CliError(f"--fix {item!r}: {exc}") from None
    return out


def _study_figures(args: argparse.Namespace, path: Path, data: StudyData) -> int:
    from analysis.plots.study_plot import plot_phase_map
    from analysis.plots.style import save_figure
    from analysis.study_maps import (
        alpha_sweep_from_study,
        format_ranking,
        parse_condition,
        phase_map,
        rank_designs,
        varying_parameters,
    )
    from instruments.units import format_quantity
    from protocols.studyfile import STATUS_FAILED, STATUS_INACCURATE

    out = args.out or path.with_name(f"{path.stem}_figures")
    can_write_folder(out, "--out")
    fixed = _parse_fix(args.fix, str(data.attrs.get("amplitude_kind", "displacement")))
    done = int((data.status != 0).sum())
    n_failed = int((data.status == STATUS_FAILED).sum())
    n_off = int((data.status == STATUS_INACCURATE).sum())
    not_ok = ", ".join(
        text
        for n, text in ((n_failed, f"{n_failed} failed"), (n_off, f"{n_off} off accuracy"))
        if n
    )
    print(f"{path}: study {data.attrs.get('name')}, {done} of {data.n_cells} cells run "
          f"({data.attrs.get('status')}){f'; {not_ok}' if not_ok else ''}")  # fmt: skip
    hidden = ("f_edge_", "alpha_actual")
    metrics = args.metric or [m for m in data.metrics if not m.startswith(hidden)]
    written: list[Path] = []
    vary = [v for v in varying_parameters(data) if v not in fixed]
    reduce = args.reduce or "mean"
    map_fixed = dict(fixed)
    # the axes: as given, else the first varied parameters (the amplitude among them, last):
    # a study over one parameter at several amplitudes draws it against the amplitude (before,
    # the amplitude was held and counted as an axis too: "y: no other varied parameter")
    free = [v for v in vary if v not in (args.x, args.y)]
    x_axis = args.x or (free.pop(0) if free else None)
    y_axis = args.y or (free.pop(0) if free else None)
    if args.reduce is None and "amplitude" in vary and "amplitude" not in (x_axis, y_axis):
        # a mean over drive amplitudes mixes regimes: the output peak's mean of 4.39 kHz (at
        # 0.5 um) and 7.45 kHz (at 2 um) drew 5.9 kHz, a peak no run has
        top = float(max(data.parameters["amplitude"]))
        map_fixed["amplitude"] = top
        kind = str(data.attrs.get("amplitude_kind", "displacement"))
        shown = format_quantity(top, "length" if kind == "displacement" else "force")
        print(
            f"maps at the largest drive amplitude, {shown} (--fix amplitude=... for another, "
            "--reduce mean to average over amplitudes)"
        )
    if x_axis is not None and y_axis is not None:
        for metric in metrics:
            try:
                pm = phase_map(data, metric, x_axis, y_axis, fixed=map_fixed, reduce=reduce)
            except ValueError as exc:
                raise CliError(str(exc)) from None
            written += save_figure(plot_phase_map(pm, data.units), out, f"map_{metric}")
    else:
        print(f"skipped phase diagrams: they need two varied parameters (varied: {vary})")
    if "alpha" in vary:
        from analysis.alpha_sweep import format_alpha_sweep, write_alpha_sweep

        try:
            sweep = alpha_sweep_from_study(data, fixed=fixed)
        except ValueError as exc:
            print(f"skipped alpha_sweep (Fig. 4): {exc}")
        else:
            print(format_alpha_sweep(sweep))
            written += write_alpha_sweep(sweep, out)
    target = args.target or ("asymmetry_ratio" if "asymmetry_ratio" in data.metrics else metrics[0])
    try:
        where = [parse_condition(w) for w in args.where]
        # ranked where the maps were drawn: at the largest amplitude unless told (the ranking
        # mixed amplitudes: the example's top 7 were 0.5 um cells the maps did not show)
        rank_fixed = dict(fixed)
        if "amplitude" in map_fixed and "amplitude" not in fixed:
            rank_fixed["amplitude"] = map_fixed["amplitude"]
        rows = rank_designs(data, target, top=args.top, fixed=rank_fixed, where=where)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    table = format_ranking(rows, data, target)
    if args.where:
        table += f"\n(among cells with {' and '.join(args.where)})"
    if "amplitude" in rank_fixed and "amplitude" not in fixed:
        table += "\n(at the largest drive amplitude, as the maps; --fix amplitude=... for another)"
    print(table)
    out.mkdir(parents=True, exist_ok=True)
    ranking = out / "best_designs.txt"
    ranking.write_text(table + "\n")
    written.append(ranking)
    for p in written:
        print(f"written {p}")
    return 0
