"""``biafc accuracy``: error against run time of the integrators on built-in scenes.

Each scene (``linear``: 0.01 delta0, contacts closed; ``highamp``: 4 um, contacts opening) is one
burst drive on the chain. Its converged reference (``yoshida6``, step halving, cached in the user
cache folder, ``$BIAFC_CACHE_DIR`` to move it) is compared with the compiled splittings over a
ladder of steps and with ``solve_ivp`` DOP853/RK45 over a ladder of tolerances. Prints a table
(wall time, steps, right-hand-side evaluations, relative L2 errors at the driven, far and worst
cylinder) and each fixed-step method's observed order; ``--plot`` draws the work-precision
diagram, ``--json`` prints everything as JSON instead.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from daq.cli.biafc import CliError
from daq.cli.out_check import can_write
from daq.cli.simulate_request import simulate_request_error
from instruments.burst import Burst
from instruments.units import UnitError, parse_quantity

SCENE_CHOICES = ("linear", "highamp", "both")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scene", default="both", help="linear, highamp or both (default both)")
    parser.add_argument("--chain", type=Path, help="chain file (YAML); default: the paper's")
    parser.add_argument("--direction", help="override the scene's drive direction: ltr or rtl")
    parser.add_argument(
        "--amplitude", help="override the scene's amplitude, with unit: '2um' or '12N'"
    )
    parser.add_argument("--duration", help="window (default 10 ms; 2 ms with --quick)")
    parser.add_argument("--rate", default="250 kS/s", help="record rate (default 250 kS/s)")
    parser.add_argument("--plot", type=Path, help="write the work-precision diagram (PNG)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of the table")
    parser.add_argument("--quick", action="store_true", help="short window and ladders (tests)")
    parser.add_argument("--no-cache", action="store_true", help="recompute the references")


def _quantity(text: str, dimension: str, option: str) -> float:
    try:
        value = parse_quantity(text, dimension, field=option)
    except UnitError as exc:
        raise CliError(str(exc)) from None
    if not (math.isfinite(value) and value > 0):
        raise CliError(f"{option}: must be finite and > 0, got {text!r}")
    return value


def _scenes(args: argparse.Namespace) -> list[Any]:
    from dataclasses import replace

    from daq.cli.simulate import DEFAULT_F_HZ, parse_amplitude
    from sim_backend import dem
    from sim_backend.dem.accuracy_scenes import builtin_scene

    if args.scene not in SCENE_CHOICES:
        raise CliError(f"--scene: unknown scene {args.scene!r}; choose from linear, highamp, both")
    if args.direction is not None and args.direction not in ("ltr", "rtl"):
        raise CliError(f"--direction: {args.direction!r} is not ltr or rtl")
    default_duration = "2 ms" if args.quick else "10 ms"
    duration = _quantity(args.duration or default_duration, "time", "--duration")
    rate = _quantity(args.rate, "sample_rate", "--rate")
    override = parse_amplitude(args.amplitude) if args.amplitude is not None else None
    try:
        spec = dem.load_chain_spec(args.chain) if args.chain else dem.default_chain_spec()
    except dem.ChainFileError as exc:
        raise CliError(str(exc)) from None
    names = ("linear", "highamp") if args.scene == "both" else (args.scene,)
    out = []
    for name in names:
        scene = builtin_scene(name, chain_spec=spec, duration_s=duration, sample_rate_Hz=rate)
        if args.direction is not None:
            scene = replace(
                scene, direction=args.direction, f_center_Hz=DEFAULT_F_HZ[args.direction]
            )
        if override is not None:
            scene = replace(scene, kind=override[0], amplitude=override[1])
        # the scene's burst against its record, and its size (a reference run keeps every
        # cylinder), as biafc simulate checks them
        burst = Burst(scene.f_center_Hz, cycles=scene.cycles)
        n_records = (spec.n_cylinders or len(spec.lengths or ())) + 1
        why = simulate_request_error(
            duration, rate, burst, n_records, burst_option="--scene", frequency_option=None
        )
        if why is not None:
            raise CliError(why)
        out.append(scene)
    return out


def format_report(report: Any) -> str:
    """The table of one :class:`sim_backend.dem.accuracy.SceneReport`."""
    ref = report.reference
    lines = [
        f"== scene {report.scene}: {report.description}",
        f"   {report.amplitude:g} {report.amplitude_units}, {report.duration_s * 1e3:g} ms at "
        f"{report.sample_rate_Hz / 1e3:g} kS/s",
        f"   reference: {ref['integrator']} at dt = {ref['dt_s'] * 1e9:g} ns, last halving changed "
        f"{ref['change_rel']:.2e} (tolerance {ref['tolerance_rel']:.0e}, "
        f"{'converged' if ref['converged'] else 'NOT converged'}), "
        + ("from cache" if ref["from_cache"] else f"computed in {ref['wall_s']:.1f} s"),
        f"   {'method':<13} {'dt / rtol':>10} {'wall_s':>8} {'steps':>8} {'rhs_evals':>10} "
        f"{'err_driven':>10} {'err_far':>10} {'err_worst':>10}",
    ]
    for m in report.measurements:
        setting = f"{m.setting * 1e6:g} us" if m.setting_name == "dt_s" else f"{m.setting:.0e}"
        lines.append(
            f"   {m.method:<13} {setting:>10} {m.wall_s:8.3f} {m.steps:8d} {m.rhs_evals:10d} "
            f"{m.err_driven:10.2e} {m.err_far:10.2e} {m.err_worst:10.2e}"
        )
    orders = ", ".join(
        f"{name} {'n/a' if p is None else f'{p:.2f}'} (nominal {report.nominal_orders[name]})"
        for name, p in report.orders.items()
    )
    lines.append(f"   observed orders (worst cylinder): {orders}")
    local = "; ".join(
        f"{name} " + " ".join(f"{p:.2f}" for p in slopes)
        for name, slopes in report.local_orders.items()
    )
    lines.append(f"   local orders, coarse to fine: {local}")
    return "\n".join(lines)


def plot_work_precision(reports: list[Any], path: Path) -> None:
    """Work-precision diagram: worst-cylinder error against wall time, log-log, one line per
    method, one panel per scene (matplotlib, Agg, no pyplot)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5.5 * len(reports), 4.6), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(reports), squeeze=False)[0]
    markers = "osD^vP*X"
    for ax, rep in zip(axes, reports, strict=True):
        methods = list(dict.fromkeys(m.method for m in rep.measurements))
        for k, name in enumerate(methods):
            rows = [m for m in rep.measurements if m.method == name]
            label = name if name not in rep.orders else f"{name} (p = {rep.orders[name] or 0:.1f})"
            ax.loglog(
                [m.wall_s for m in rows],
                [m.err_worst for m in rows],
                marker=markers[k % len(markers)],
                label=label,
            )
        ref = rep.reference
        ax.axhline(max(ref["change_rel"], 1e-300), color="0.6", ls=":", lw=1)
        amp = (
            f"{rep.amplitude * 1e6:.3g} um"
            if rep.amplitude_units == "m"
            else f"{rep.amplitude:.3g} N"
        )
        ax.set_title(f"{rep.scene}: {amp}, {rep.duration_s * 1e3:g} ms")
        ax.set_xlabel("wall time (s, one trajectory)")
        ax.set_ylabel("relative L2 error of velocity, worst cylinder")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(
        "work-precision: compiled splittings vs scipy solve_ivp (dotted: reference change)"
    )
    fig.savefig(path, dpi=110)


def run(args: argparse.Namespace) -> int:
    import sys

    from daq.progress import ProgressDisplay
    from sim_backend.dem.accuracy import accuracy_runs, run_accuracy

    scenes = _scenes(args)
    if args.plot is not None:
        if args.plot.suffix.lower() != ".png":
            raise CliError(f"--plot: {args.plot} must end in .png")
        parent = args.plot.parent if str(args.plot.parent) else Path(".")
        if not parent.is_dir():
            raise CliError(f"--plot: folder {parent} does not exist")
        can_write(args.plot, "--plot")  # before the runs, not after
    reports = []
    total = len(scenes) * accuracy_runs(quick=args.quick)
    with ProgressDisplay(total, unit="run", label="biafc accuracy", stream=sys.stderr) as bar:

        def step(what: str) -> None:
            bar.update(bar.done + 1, detail=what)

        for scene in scenes:
            report = run_accuracy(
                scene, quick=args.quick, use_cache=not args.no_cache, on_step=step
            )
            reports.append(report)
            if not args.json:
                print(format_report(report), flush=True)  # stdout (rich keeps the bar apart)
    if args.plot is not None:
        plot_work_precision(reports, args.plot)
        if not args.json:
            print(f"work-precision diagram: {args.plot}")
    if args.json:
        print(json.dumps({"scenes": [r.as_dict() for r in reports]}, indent=2))
    return 0
