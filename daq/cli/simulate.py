"""``biafc simulate --direction ltr|rtl --amplitude 2um|12N --out RUN.h5``: one DEM run.

``--explain`` prints the scene's plan (:mod:`sim_backend.dem.scene`: which resonators, contact
model, window and outputs the run needs, with error bounds and savings) and exits without
running; ``--out`` is then not needed. A run uses the full model unless ``--lean`` is given:
then it runs that plan (condensed resonators, linear solution, early stop where the plan allows
them), prints it, and stores it in the run file's ``/simulation`` attributes (``scene_plan_json``).

The amplitude's unit picks the drive: a length (``2 um``) is the peak displacement of the
actuator, a moving Hertz wall; a force (``12 N``) is the peak force on the end cylinder. The run
is written in the run-file layout (backend ``"dem"``, one amplitude, every cylinder done) and a
summary is printed: the transmitted energy ratio (far-end over entry cylinder) and the far end's
spectral peak, with the conversion verdict beside it (:func:`analysis.summary.verdict_reason`:
one run has no linear reference, so E_far/E_in must reach 1e-2; the far end always has a
largest line, a linear leak's too).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any, Literal

import numpy as np

from daq.cli.biafc import CliError
from daq.cli.out_check import can_write
from daq.cli.simulate_request import simulate_request_error, within
from instruments.burst import NAMED_BURSTS
from instruments.units import UnitError, parse_quantity
from protocols.one_line import first_line
from sim_backend.dem.integrators import integrator_error
from sim_backend.dem.step_limit import StepTooLargeError

#: the paper's input frequencies
DEFAULT_F_HZ = {"ltr": 8.92e3, "rtl": 6.63e3}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--direction", required=True, choices=("ltr", "rtl"))
    parser.add_argument(
        "--amplitude", required=True, help="burst peak with unit: '2um' (displacement) or '12N'"
    )
    parser.add_argument(
        "--out", type=Path, help="run file to create (.h5); required unless --explain"
    )
    parser.add_argument("--chain", type=Path, help="chain file (YAML); default: the paper's")
    parser.add_argument(
        "--set",
        dest="settings",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="change a chain setting (diameter=12mm, preload=4N, n_modes=5; repeatable), "
        "validated like the chain file and recorded in the run file",
    )
    parser.add_argument("--frequency", help="burst centre frequency (default 8.92 kHz / 6.63 kHz)")
    width = parser.add_mutually_exclusive_group()
    width.add_argument(
        "--burst",
        choices=tuple(NAMED_BURSTS),
        help="a named burst: narrowband (the default, 21 cycles) or five_cycle (broadband)",
    )
    width.add_argument("--cycles", type=float, help="burst length in carrier cycles (default 21)")
    width.add_argument("--width", help="burst Gaussian sigma in time with unit, e.g. '0.4 ms'")
    width.add_argument(
        "--sigma-f", help="burst Gaussian sigma in frequency with unit, e.g. '0.4 kHz'"
    )
    parser.add_argument("--duration", default="30 ms", help="recorded window (default 30 ms)")
    parser.add_argument("--rate", default="500 kS/s", help="record rate (default 500 kS/s)")
    parser.add_argument("--integrator", default="default", help="integrator name")
    parser.add_argument("--dt", help="integrator step with unit (default: the integrator's)")
    parser.add_argument("--bands", type=int, default=3, help="bands stored in /chain")
    parser.add_argument(
        "--explain",
        action="store_true",
        help="print what the scene needs (modes, nonlinearity, time, output: kept or dropped, "
        "why, error bound, saving) and exit without running",
    )
    parser.add_argument(
        "--lean",
        action="store_true",
        help="run the reduced model the scene's plan allows (see --explain) and store the plan",
    )
    parser.add_argument(
        "--no-error-estimate",
        action="store_true",
        help="skip the step-doubling error estimate (saves about a third of the run time)",
    )


def _quantity(text: str, dimension: str, option: str) -> float:
    try:
        return parse_quantity(text, dimension, field=option)
    except UnitError as exc:
        raise CliError(str(exc)) from None


def parse_amplitude(text: str) -> tuple[Literal["displacement", "force"], float]:
    """``'2um'`` -> ``('displacement', 2e-6)``; ``'12N'`` -> ``('force', 12.0)``."""
    pairs: tuple[tuple[Literal["displacement", "force"], str], ...] = (
        ("displacement", "length"),
        ("force", "force"),
    )
    for kind, dim in pairs:
        try:
            value = parse_quantity(text, dim, field="--amplitude")
        except UnitError:
            continue
        if not value > 0:
            raise CliError("--amplitude: must be > 0")
        return kind, value
    raise CliError(f"--amplitude: {text!r} needs a length (e.g. '2 um') or a force (e.g. '12 N')")


def _burst(args: argparse.Namespace, f_c: float) -> Any:
    """The burst of the command line: ``--burst``, ``--cycles``, ``--width`` or ``--sigma-f``;
    default the narrowband burst (:data:`instruments.burst.NARROWBAND_CYCLES` cycles)."""
    from instruments.burst import NARROWBAND_CYCLES, Burst, width_from_sigma_f

    if args.width is not None:
        width = _quantity(args.width, "time", "--width")
        if not width > 0:
            raise CliError("--width: must be > 0")
        return Burst(f_c, cycles=None, width_s=width)
    if args.sigma_f is not None:
        sigma_f = _quantity(args.sigma_f, "frequency", "--sigma-f")
        if not sigma_f > 0:
            raise CliError("--sigma-f: must be > 0")
        return Burst(f_c, cycles=None, width_s=width_from_sigma_f(sigma_f))
    if args.burst is not None:
        return Burst(f_c, cycles=NAMED_BURSTS[args.burst])
    return Burst(f_c, cycles=args.cycles if args.cycles is not None else NARROWBAND_CYCLES)


def _burst_option(args: argparse.Namespace) -> str:
    """The option that set the burst's length (the frequency when none did)."""
    for option, value in (
        ("--width", args.width), ("--sigma-f", args.sigma_f), ("--burst", args.burst),
        ("--cycles", args.cycles),
    ):  # fmt: skip
        if value is not None:
            return option
    return "--frequency"


def _describe(burst: Any) -> str:
    length = (
        f"{burst.cycles:g} cycles"
        if burst.cycles is not None
        else f"{burst.duration_s * 1e3:.3g} ms"
    )
    return f"{length}, sigma {burst.sigma_s * 1e3:.3g} ms / {burst.sigma_f_Hz / 1e3:.3g} kHz"


def run(args: argparse.Namespace) -> int:
    from daq.chain_info import model_chain_info
    from protocols.runfile import RunFileWriter, ScanSpec
    from sim_backend import dem

    kind, amplitude = parse_amplitude(args.amplitude)
    duration = _quantity(args.duration, "time", "--duration")
    rate = _quantity(args.rate, "sample_rate", "--rate")
    f_c = _quantity(args.frequency, "frequency", "--frequency") if args.frequency else None
    dt = _quantity(args.dt, "time", "--dt") if args.dt else None
    if not (duration > 0 and rate > 0 and (dt is None or dt > 0)):
        raise CliError("--duration, --rate and --dt must be > 0")
    if args.cycles is not None and not (math.isfinite(args.cycles) and args.cycles > 0):
        raise CliError("--cycles: must be > 0")
    if args.out is None and not args.explain:
        raise CliError("--out: required (or --explain to print the scene's plan only)")
    if args.out is not None and args.out.exists():
        raise CliError(
            f"--out: {args.out} is a folder; give a run file name (e.g. {args.out}/run.h5)"
            if args.out.is_dir()
            else f"--out: {args.out} exists already"
        )
    if args.out is not None:
        can_write(args.out, "--out")  # before the model runs, not after
    try:
        spec = dem.load_chain_with_settings(args.chain, args.settings)
    except dem.ChainFileError as exc:
        raise CliError(str(exc)) from None
    why = integrator_error(args.integrator)
    if why is not None:
        raise CliError(f"--integrator: {why}")
    chain = dem.build_chain(spec)
    if not 1 <= args.bands <= chain.n_modes + 1:
        raise CliError(f"--bands: must be in 1..{chain.n_modes + 1}")
    bands = dem.quasi_bands(chain, args.bands)
    f_center = f_c if f_c is not None else DEFAULT_F_HZ[args.direction]
    why = within("--frequency", f_center, "f_center", "frequency")
    if why is not None:
        raise CliError(why)
    try:
        burst = _burst(args, f_center)
    except ValueError as exc:  # instruments.burst's own refusal
        raise CliError(first_line(exc)) from None
    option = _burst_option(args)
    why = simulate_request_error(duration, rate, burst, chain.n + 1, burst_option=option)
    if why is not None:
        raise CliError(why)
    drive = dem.Drive(direction=args.direction, kind=kind, amplitude=amplitude, burst=burst)
    if args.explain:  # the plan only: sim_backend.dem.scene decides, nothing runs
        from sim_backend.dem.scene import Scene, plan_scene

        scene = Scene(chain, (drive,), duration, rate, record=("velocity", "drive"))
        print(plan_scene(scene).explain())
        return 0
    if args.lean and (dt is not None or args.integrator != "default"):
        raise CliError("--lean picks the model itself; drop --dt and --integrator")
    if dt is not None and not args.lean:
        _check_step(chain, drive, args.integrator, dt, rate)
    progress = _stages(args, chain, duration, dt)
    try:
        if args.lean:
            res, simulation = _run_lean(chain, drive, duration, rate)
        else:
            res, simulation = _run_full(args, chain, drive, duration, rate, dt)
        progress.update(1, detail="model run done; writing the run file", eta_s=0.2)
    finally:
        progress.close()
    simulation.update(
        drive_kind=kind,
        far_end=chain.far_end,
        chain_yaml=spec.to_yaml(),
        chain_settings=" ".join(args.settings),
        bending_mode_damping_ratio=chain.bending_damping_ratio,
        contact_dashpot_damping_ratio=chain.contact_damping_ratio,
        burst_sigma_s=burst.sigma_s,
        burst_sigma_f_Hz=burst.sigma_f_Hz,
    )
    scan = ScanSpec(
        direction=args.direction,
        amplitudes=np.array([amplitude]),
        amplitude_units=drive.units,
        cylinders=res.cylinders,
        time_s=res.time_s,
        f_center_Hz=burst.f_center_Hz,
        cycles=burst.cycles,
        width_s=burst.width_s,
        drive_units=drive.units,
    )
    try:
        args.out.parent.mkdir(parents=True, exist_ok=True)  # as run_protocol makes its folder
        writer = RunFileWriter.create(
            args.out, backend="dem", chain=model_chain_info(chain, bands), scans=[scan],
            simulation=simulation,
        )  # fmt: skip
    except OSError as exc:
        raise CliError(f"--out: cannot create {args.out} ({exc})") from None
    try:
        for c in range(res.cylinders.size):
            writer.write_point(args.direction, 0, c, res.velocity[0, c], res.drive[0])
        writer.log(
            "info", f"DEM run: {kind} {amplitude:g} {drive.units}, {simulation['integrator']}"
        )
        writer.close("complete")
    except BaseException:
        writer.close("failed")
        raise
    from analysis.summary import summary_rows, verdict_reason
    from analysis.sweep import amplitude_sweep, output_peak_definition
    from protocols.runfile import read_run

    stored = read_run(args.out)
    sweep = amplitude_sweep(stored.scans[args.direction], stored.chain)
    # the largest far-end line is there whether or not anything converted: the verdict
    # (analysis.summary's rule for one amplitude) goes beside it
    verdict = verdict_reason(summary_rows(sweep, stored.scans[args.direction])[0])
    step = "" if simulation["order"] == 0 else f" dt = {simulation['dt_s'] * 1e6:.3g} us"
    lost = "dissipated by the damping" if chain.damped else "the integrator's energy error"
    print(
        f"{args.out}: {args.direction} {kind} {amplitude:g} {drive.units} at "
        f"{burst.f_center_Hz / 1e3:g} kHz ({_describe(burst)}), {chain.n} cylinders, "
        f"{res.time_s.size} samples, "
        f"{simulation['integrator']}{step}, {simulation['wall_s']:.2f} s"
    )
    print(
        f"error estimate (worst cylinder, relative L2): {simulation['error_estimate_rel']:.2g} "
        f"[{simulation['error_estimate_method']}]; input work not in the chain at the end "
        f"{simulation['work_not_in_chain_rel']:.2g} ({lost})"
    )
    print(
        f"transmitted energy ratio E_far/E_in (cylinder {sweep.far} / cylinder {sweep.entry}): "
        f"{float(sweep.transmission[0]):.4g}"
    )
    print(
        f"{output_peak_definition(sweep)}: {float(sweep.output_Hz[0]) / 1e3:.3f} kHz "
        f"(input {float(sweep.input_Hz[0]) / 1e3:.3f} kHz, detuning "
        f"{float(sweep.detuning_Hz[0]) / 1e3:+.3f} kHz; {verdict})"
    )
    print(
        f"far/near rms ratio (cylinder {sweep.far} / cylinder {sweep.entry}): "
        f"{math.sqrt(float(sweep.transmission[0])):.4g}"
    )
    return 0


def _check_step(chain: Any, drive: Any, integrator: str, dt: float, rate: float) -> None:
    """Refuse a ``--dt`` the model would not run at: one above the chain's stability limit for
    the integrator (:mod:`sim_backend.dem.step_limit`), or one coarser than the record period
    (the model steps a whole number of times per sample, so it would silently step at the
    period). A finer stable step is honoured (as the largest ``period / n <= dt``)."""
    from instruments.units import format_quantity
    from sim_backend.dem.simulation import DEFAULT_INTEGRATOR
    from sim_backend.dem.step_limit import (
        largest_stable_step,
        reference_overlap_m,
        stable_up_to,
    )

    period = 1.0 / rate
    if dt <= period:
        return  # the model's own check refuses an unstable step (StepTooLargeError)
    name = DEFAULT_INTEGRATOR if integrator == "default" else integrator
    overlap = reference_overlap_m(chain, [drive])
    given = format_quantity(dt, "time")
    if not stable_up_to(chain, name, dt, overlap):
        lim = largest_stable_step(chain, name, overlap)
        use = format_quantity(min(lim.h_max_s, period), "time")
        if period < lim.h_max_s:
            use += f" (the record period at --rate {format_quantity(rate, 'sample_rate')})"
        raise CliError(
            f"--dt {given}: unstable on this chain, whose stability limit for {name} is "
            f"{format_quantity(lim.h_max_s, 'time')} (linearised step map); use --dt <= {use}"
        )
    raise CliError(
        f"--dt {given}: stable on this chain but coarser than the record period "
        f"{format_quantity(period, 'time')} (--rate {format_quantity(rate, 'sample_rate')}), "
        "and the model steps at least once per sample; use --dt <= "
        f"{format_quantity(period, 'time')}, or a lower --rate"
    )


def _stages(args: argparse.Namespace, chain: Any, duration: float, dt: float | None) -> Any:
    """The progress display of a simulation (:mod:`daq.progress`, on stderr): the model run,
    its ETA from the model's cost (:mod:`daq.engine.eta`, with the first compile)."""
    import sys

    from daq.engine.eta import COMPILE_S, dem_run_estimate_s, model_compiled
    from daq.progress import ProgressDisplay
    from sim_backend.dem.simulation import DEFAULT_DT_S, DEFAULT_INTEGRATOR

    name = DEFAULT_INTEGRATOR if args.integrator == "default" else args.integrator
    step = dt if dt is not None else DEFAULT_DT_S.get(name, 1e-6)
    est = dem_run_estimate_s(chain.n, chain.n_modes, duration, step, not args.no_error_estimate)
    compiled = model_compiled()
    first = "" if compiled else f"; compiling the model first (once, about {COMPILE_S:.0f} s)"
    display = ProgressDisplay(1, unit="model run", label="biafc simulate", stream=sys.stderr)
    if display.live:  # piped: no line before the run (an error stays one line)
        est += 0.0 if compiled else COMPILE_S
        display.update(0, detail=f"{name}{first}", eta_s=est)
    return display


def _run_full(
    args: argparse.Namespace, chain: Any, drive: Any, duration: float, rate: float,
    dt: float | None,
) -> tuple[Any, dict[str, Any]]:  # fmt: skip
    """The full model: (``SimResult``, the run file's ``/simulation`` attributes)."""
    from sim_backend import dem

    try:
        res = dem.simulate(
            chain, [drive], duration_s=duration, sample_rate_Hz=rate,
            integrator=args.integrator, dt_s=dt, error_estimate=not args.no_error_estimate,
        )  # fmt: skip
    except StepTooLargeError as exc:
        raise CliError(f"--dt: {exc}") from None
    meta = res.meta
    if not meta["finite"]:
        raise CliError(
            "simulation diverged (non-finite velocity): try a smaller --dt, or a smaller "
            f"--amplitude ({args.amplitude} drives the chain far beyond its static overlap)"
            if args.dt is None
            else "simulation diverged (non-finite velocity); try a smaller --dt or --amplitude"
        )
    return res, {
        "integrator": meta["integrator"],
        "order": int(meta["order"]),
        "dt_s": float(meta["dt_s"]),
        "work_not_in_chain_rel": float(meta["work_not_in_chain_rel"][0]),
        "error_estimate_rel": float(meta.get("error_estimate_rel", [float("nan")])[0]),
        "error_estimate_method": str(meta.get("error_estimate_method", "none (not requested)")),
        "input_work_J": float(meta["input_work_J"][0]),
        "damped": bool(meta["damped"]),
        "wall_s": float(meta["wall_s"]),
    }


def _run_lean(chain: Any, drive: Any, duration: float, rate: float) -> tuple[Any, dict[str, Any]]:
    """The plan's reduced model (:func:`sim_backend.dem.scene.run_scene`), printed first:
    (``SceneResult``, the run file's ``/simulation`` attributes, the plan as JSON included).
    The error estimate is the plan's own bound: the linearisation error for the linear solution,
    else the largest bound of the decisions taken (condensation, early stop)."""
    import json

    from sim_backend import dem
    from sim_backend.dem.scene import Scene, plan_scene, run_scene

    plan = plan_scene(Scene(chain, (drive,), duration, rate, record=("velocity", "drive")))
    print(plan.explain())
    res = run_scene(plan)
    meta = res.meta
    if res.velocity is None or not np.all(np.isfinite(res.velocity)):
        raise CliError("simulation diverged (non-finite velocity)")
    bounds = [d.error_bound for d in plan.decisions if d.reduced and d.error_bound is not None]
    if meta["solver"] == "linear-modal":
        estimate = float(meta["linear_error_est"])
        method = "linearisation error bound of the scene plan"
        integrator, order, dt_s, residual = "linear-modal", 0, 1.0 / rate, float("nan")
    else:
        estimate = max(bounds, default=float("nan"))
        method = "largest error bound of the scene plan's reductions"
        integrator, order = str(meta["integrator"]), int(dem.INTEGRATORS[meta["integrator"]][0])
        dt_s = float(meta["dt_s"])
        residual = float(np.asarray(meta["work_not_in_chain_rel"])[0])
    return res, {
        "integrator": integrator,
        "order": order,
        "dt_s": dt_s,  # the linear solution: the record's sample period
        "work_not_in_chain_rel": residual,
        "error_estimate_rel": estimate,
        "error_estimate_method": method,
        "damped": chain.damped,
        "wall_s": float(meta["wall_s"]),
        "scene_plan_json": json.dumps(plan.as_dict(), default=float),
    }
