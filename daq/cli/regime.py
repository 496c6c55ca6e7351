"""``biafc regime [--from 0.01um] [--to 4um] [--count 12] [--set KEY=VALUE] --out DIR``.

The regime of a chain in one look, from the model: both directions at ``count`` drive
amplitudes (log spaced) in one batched DEM run (``sim_backend.dem.simulate``), written as a run
file ``DIR/regime.h5`` (every cylinder; backend ``"dem"``) and drawn as ``DIR/regime.png``/
``.pdf`` (:mod:`analysis.plots.regime_plot`: far/near rms ratio against amplitude with the
linear floor, and the far-end output peak). The table of the figure is printed. The burst is the
narrowband default unless ``--burst five_cycle`` or ``--cycles N`` is given. ``biafc figures``
draws the same figure for any run file holding an amplitude sweep (simulated or measured).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any, Literal

import numpy as np

from daq.cli.biafc import CliError
from daq.cli.out_check import can_write_folder
from daq.cli.simulate_request import simulate_request_error
from instruments.burst import NAMED_BURSTS
from instruments.units import UnitError, parse_quantity

#: the paper's input frequencies
DEFAULT_F_HZ = {"ltr": 8.92e3, "rtl": 6.63e3}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--out", type=Path, required=True, help="folder for regime.h5 and the figure"
    )
    parser.add_argument("--chain", type=Path, help="chain file (YAML); default: the paper's")
    parser.add_argument(
        "--set",
        dest="settings",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="change a chain setting (diameter=12mm, preload=4N, n_modes=5; repeatable)",
    )
    parser.add_argument("--from", dest="start", default="0.01 um", help="smallest amplitude")
    parser.add_argument("--to", dest="stop", default="4 um", help="largest amplitude")
    parser.add_argument("--count", type=int, default=12, help="amplitudes, log spaced (>= 2)")
    width = parser.add_mutually_exclusive_group()
    width.add_argument("--burst", choices=tuple(NAMED_BURSTS), help="a named burst")
    width.add_argument("--cycles", type=float, help="burst length in carrier cycles")
    parser.add_argument("--duration", default="30 ms", help="recorded window (default 30 ms)")
    parser.add_argument("--rate", default="250 kS/s", help="record rate (default 250 kS/s)")


def _q(text: str, dimension: str, option: str) -> float:
    try:
        value = parse_quantity(text, dimension, field=option)
    except UnitError as exc:
        raise CliError(str(exc)) from None
    if not (math.isfinite(value) and value > 0):
        raise CliError(f"{option}: must be > 0")
    return value


def run(args: argparse.Namespace) -> int:
    from analysis.plots.regime_plot import plot_regime, rms_ratio
    from analysis.plots.style import save_figure
    from analysis.sweep import amplitude_sweep
    from daq.chain_info import model_chain_info
    from instruments.burst import NARROWBAND_CYCLES, Burst
    from protocols.runfile import RunFileWriter, ScanSpec, read_run
    from sim_backend import dem

    lo = _q(args.start, "length", "--from")
    hi = _q(args.stop, "length", "--to")
    if not hi > lo:
        raise CliError("--to: must be above --from")
    if not 2 <= args.count <= 256:
        raise CliError("--count: must be in 2..256")
    duration = _q(args.duration, "time", "--duration")
    rate = _q(args.rate, "sample_rate", "--rate")
    cycles = (
        NAMED_BURSTS[args.burst]
        if args.burst
        else (args.cycles if args.cycles is not None else NARROWBAND_CYCLES)
    )
    if not (math.isfinite(cycles) and cycles > 0):
        raise CliError("--cycles: must be > 0")
    out: Path = args.out
    run_path = out / "regime.h5"
    if run_path.exists():
        raise CliError(f"--out: {run_path} exists already")
    can_write_folder(out, "--out")  # before the model runs, not after
    try:
        spec = dem.load_chain_with_settings(args.chain, args.settings)
    except dem.ChainFileError as exc:
        raise CliError(str(exc)) from None
    chain = dem.build_chain(spec)
    bands = dem.quasi_bands(chain, min(3, chain.n_modes + 1))
    amps = np.geomspace(lo, hi, args.count)
    directions: tuple[Literal["ltr", "rtl"], ...] = ("ltr", "rtl")
    bursts = {d: Burst(DEFAULT_F_HZ[d], cycles=cycles) for d in directions}
    drives = [
        dem.Drive(direction=d, kind="displacement", amplitude=float(a), burst=bursts[d])
        for d in directions
        for a in amps
    ]
    option = "--burst" if args.burst else "--cycles"
    for k, d in enumerate(directions):  # each burst against the record; the batch's size once
        why = simulate_request_error(
            duration, rate, bursts[d], len(drives) * (chain.n + 1) if k == 0 else 1,
            burst_option=option, records_option=f"--count {args.count}", frequency_option=None,
        )  # fmt: skip
        if why is not None:
            raise CliError(why)
    print(
        f"regime: {len(drives)} DEM runs in one batch ({args.count} amplitudes "
        f"{lo * 1e6:g}-{hi * 1e6:g} um x 2 directions, {cycles:g}-cycle bursts), "
        f"{chain.n} cylinders"
    )
    res = dem.simulate(chain, drives, duration_s=duration, sample_rate_Hz=rate)
    if not res.meta["finite"]:
        raise CliError("simulation diverged (non-finite velocity)")
    scans = [
        ScanSpec(
            direction=d,
            amplitudes=amps,
            amplitude_units="m",
            cylinders=res.cylinders,
            time_s=res.time_s,
            f_center_Hz=bursts[d].f_center_Hz,
            cycles=cycles,
            drive_units="m",
        )
        for d in directions
    ]
    simulation = {
        "integrator": str(res.meta["integrator"]),
        "dt_s": float(res.meta["dt_s"]),
        "chain_yaml": spec.to_yaml(),
        "chain_settings": " ".join(args.settings),
        "wall_s": float(res.meta["wall_s"]),
    }
    out.mkdir(parents=True, exist_ok=True)
    writer = RunFileWriter.create(
        run_path, backend="dem", chain=model_chain_info(chain, bands), scans=scans,
        simulation=simulation,
    )  # fmt: skip
    try:
        for k, d in enumerate(directions):
            for a in range(amps.size):
                r = k * amps.size + a
                for c in range(res.cylinders.size):
                    writer.write_point(d, a, c, res.velocity[r, c], res.drive[r])
        writer.close("complete")
    except BaseException:
        writer.close("failed")
        raise
    stored = read_run(run_path)
    sweeps: dict[str, Any] = {d: amplitude_sweep(stored.scans[d], stored.chain) for d in directions}
    paths = save_figure(plot_regime(sweeps), out, "regime")
    print(f"{'amplitude':>12}  {'LTR rms':>9} {'LTR f_out':>9}  {'RTL rms':>9} {'RTL f_out':>9}")
    ratios = {d: rms_ratio(sweeps[d]) for d in directions}
    for a in range(amps.size):
        cells = "  ".join(
            f"{ratios[d][a]:9.3g} {sweeps[d].output_Hz[a] / 1e3:7.3f} kHz"[:21] for d in directions
        )
        print(f"{amps[a] * 1e6:9.4g} um  {cells}")
    for d in directions:
        gain = ratios[d][-1] / ratios[d][0]
        print(f"{d}: linear floor {ratios[d][0]:.3g}, x{gain:.3g} at {amps[-1] * 1e6:g} um")
    print(f"written {run_path}, " + ", ".join(str(p) for p in paths))
    return 0
