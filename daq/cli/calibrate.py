"""``biafc calibrate RUN.h5 --fit F0,damping,diameter,stroke [--out fitted_chain.yaml]``.

Fits the chain model to the run's low-amplitude (linear) points with the linear-response
solver (:mod:`analysis.calibrate`), prints each fitted value with its uncertainty, the
correlations and the residual before and after, and writes the fitted chain file (default
``<RUN>_fitted_chain.yaml`` beside the run file; the fitted piezo stroke, a bench quantity, is
in its header and in ``<out>.json``). When the run also holds nonlinear points, it then
predicts them with the DEM from the start values and from the fit (``biafc compare``'s figure
of merit on every point, before and after): the test of the model from its linear fit alone.
``--figures DIR`` writes the before/after spectra (``calibration``) and, unless ``--no-check``,
the comparison figures of the fitted model in ``DIR/compare_after`` (``biafc compare``'s).

What the fit is doing goes to stderr as it goes (the parameters, points and residuals; each
stage; every second the evaluations so far and the relative residual); ``-q`` silences it.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from pathlib import Path

from daq.cli.biafc import CliError
from daq.cli.out_check import can_write, can_write_folder
from daq.cli.written import print_written

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_file", type=Path, help="run file (HDF5) with a measured scan")
    parser.add_argument(
        "--fit",
        default="F0,damping,diameter,stroke",
        help="parameters to fit, comma-separated: F0, diameter, damping (the resonators' "
        "modal damping ratio), stroke (the piezo's m/V), E (Young's modulus); "
        "default F0,damping,diameter,stroke",
    )
    parser.add_argument("--chain", type=Path, help="start chain (YAML); default: the file's")
    parser.add_argument("--out", type=Path, help="fitted chain file to write (.yaml)")
    parser.add_argument("--figures", type=Path, help="folder for before/after figures")
    parser.add_argument(
        "--nonlinear",
        action="store_true",
        help="after the linear fit, refine on every unclipped point with the batched DEM",
    )
    parser.add_argument(
        "--no-check",
        action="store_true",
        help="skip predicting the nonlinear points with the DEM before and after the fit",
    )
    parser.add_argument(
        "-q", "--quiet", action="store_true", help="no progress lines (on stderr) during the fit"
    )


def _progress(quiet: bool) -> Callable[[str], None] | None:
    """Where the fit's progress goes: a line to stderr at once, or nowhere with ``-q``."""
    if quiet:
        return None

    def say(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    return say


def run(args: argparse.Namespace) -> int:
    from analysis.calibrate import CalibrationError, calibrate, parse_fit
    from daq.cli.run_input import read_run_and_chain

    path: Path = args.run_file
    if not path.exists():
        raise CliError(f"run file {path} does not exist")
    try:
        names = parse_fit(args.fit)
    except CalibrationError as exc:
        raise CliError(str(exc)) from None
    data, spec = read_run_and_chain(path, args.chain)
    out: Path = args.out or path.with_name(f"{path.stem}_fitted_chain.yaml")
    _refuse_existing(out)
    can_write(out, "--out")
    if args.figures is not None:
        can_write_folder(args.figures, "--figures")
    say = _progress(args.quiet)
    try:
        result = calibrate(data, names, chain_spec=spec, nonlinear=args.nonlinear, progress=say)
    except CalibrationError as exc:
        raise CliError(str(exc)) from None
    print(result.table(), flush=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(result.chain_yaml(path.name), encoding="utf-8")
    summary = result.as_dict()
    stroke_arg = ""
    if result.stroke_m_per_V is not None and "stroke" in result.names:
        stroke_arg = f" --piezo-stroke '{result.stroke_m_per_V * 1e6:.6g} um/V'"
    if not args.no_check:
        summary["prediction"] = _check(data, spec, result, args.figures, say)
    if args.figures is not None:
        _figures(data, spec, result, args.figures)
    json_path = out.with_suffix(".json")
    json_path.write_text(json.dumps(summary, indent=2), encoding="utf-8")
    print(f"written {out}")
    print(f"written {json_path}")
    print(f"next: biafc compare {path} --chain {out}{stroke_arg}")
    return 0 if result.success else 1


def _refuse_existing(out: Path) -> None:
    """A chain file (or its ``.json`` beside it) already there is not overwritten: it may be a
    hand-made chain or an earlier fit."""
    for target in (out, out.with_suffix(".json")):
        if target.exists() and not target.is_dir():
            raise CliError(f"--out: {target} exists already; write a new file (--out {_free(out)})")


def _free(out: Path) -> Path:
    """The first ``NAME_2.yaml``, ``NAME_3.yaml``... beside ``out`` whose ``.json`` is free too
    (a chain file; run_store's free name gave ``.h5`` to a name without a suffix)."""
    suffix = out.suffix or ".yaml"
    for k in range(2, 10_000):
        cand = out.with_name(f"{out.stem}_{k}{suffix}")
        if not cand.exists() and not cand.with_suffix(".json").exists():
            return cand
    return out.with_name(f"{out.stem}_new{suffix}")


def _check(data, spec, result, figures: Path | None, say=None) -> dict[str, float | None]:  # type: ignore[no-untyped-def]
    """Figure of merit of the DEM prediction of every point, from the start and from the fit;
    with ``figures``, then ``biafc compare``'s figures of the fit in ``figures/compare_after``
    (each said as written: they had been written and never mentioned)."""
    from analysis.compare_report import compare_run, write_compare

    if say is not None:
        say("predicting every point with the DEM, from the start values and from the fit")
    before = compare_run(data, None, chain_spec=spec).comparison
    after_report = compare_run(
        data,
        None,
        chain_spec=result.spec,
        piezo_stroke_m_per_V=result.stroke_m_per_V if "stroke" in result.names else None,
    )
    after = after_report.comparison

    def f(x: float) -> float | None:
        return x if math.isfinite(x) else None

    nf = after.n_noise_floor  # far records at the noise floor: bounds, not compared
    floor_note = (
        f", {nf} far record{'' if nf == 1 else 's'} at the noise floor left out" if nf else ""
    )
    noise_alone = after.spectral_noise_figure
    alone = f", noise alone {noise_alone:.3f}" if math.isfinite(noise_alone) else ""
    print(
        f"DEM prediction of {after.counts.get('ok', 0) - nf} compared points (linear and "
        f"nonlinear{floor_note}), figure of merit: {before.figure_of_merit:.3f} from the start "
        f"values, {after.figure_of_merit:.3f} from the fit{alone} (time-domain "
        f"{before.time_figure:.3f} -> "
        f"{after.time_figure:.3f}, noise floor "
        + (f"{after.noise_figure:.3f})" if math.isfinite(after.noise_figure) else "n/a)"),
        flush=True,
    )
    if figures is not None:
        write_compare(after_report, data, figures / "compare_after", print_written)
        print(f"written {after_report.csv_path}")
        print(f"written {after_report.json_path}")
    return {
        "figure_of_merit_before": f(before.figure_of_merit),
        "figure_of_merit_after": f(after.figure_of_merit),
        "time_residual_before": f(before.time_figure),
        "time_residual_after": f(after.time_figure),
        "noise_floor": f(after.noise_figure),
    }


def _figures(data, spec, result, folder: Path) -> None:  # type: ignore[no-untyped-def]
    from analysis.calibrate import fit_spectra
    from analysis.plots.calibration_plot import plot_calibration
    from analysis.plots.style import save_figure

    paths = save_figure(plot_calibration(fit_spectra(data, result, spec)), folder, "calibration")
    print_written("calibration", paths)
