"""``biafc stability [--case NAME] [--fast] [--plot DIR]``: the stiff and extreme DEM cases.

Prints one row per case (what it stresses, the step and why, max |v|, the energy residual and the
verdict with its reason) followed by the case's further numbers; exit status 1 when a case fails.
``--plot DIR`` writes ``DIR/<case>.png`` (the velocity field, and the case's extra curve).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

from daq.cli.biafc import CliError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--case", action="append", help="run only this case (repeatable)")
    parser.add_argument("--fast", action="store_true", help="short windows (the tests' ones)")
    parser.add_argument("--plot", type=Path, metavar="DIR", help="write a figure per case")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")


def _figure(res: Any, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    n_ax = 2 if res.series is not None else 1
    fig, axes = plt.subplots(1, n_ax, figsize=(6.5 * n_ax, 4.2), squeeze=False)
    ax = axes[0, 0]
    v = np.abs(np.nan_to_num(res.velocity, nan=0.0, posinf=0.0))
    if v.size:
        vmax = max(float(v.max()), 1e-300)
        img = ax.imshow(
            np.log10(np.maximum(v, vmax * 1e-6)), aspect="auto", origin="lower",
            extent=(0.0, float(res.time_s[-1]) * 1e3, 0.5, v.shape[0] + 0.5),
            vmin=math.log10(vmax) - 6, vmax=math.log10(vmax), cmap="magma",
        )  # fmt: skip
        fig.colorbar(img, ax=ax, label="log10 |v| (m/s)")
    ax.set_xlabel("time (ms)")
    ax.set_ylabel("cylinder (recorded index)")
    verdict = "PASS" if res.passed else "FAIL"
    ax.set_title(f"{res.name}: {verdict}, dt = {res.dt_s * 1e6:.3g} us", fontsize=10)
    if res.series is not None:
        label, x, y = res.series
        ax2 = axes[0, 1]
        ax2.plot(x, y, "o-")
        ax2.axhline(res.tolerance, color="r", ls="--", label=f"tolerance {res.tolerance:g}")
        ax2.axhline(-res.tolerance, color="r", ls="--")
        ax2.set_xlabel("window (s)")
        ax2.set_ylabel("(H_end - H_0 - W) / W")
        ax2.set_title(label, fontsize=10)
        ax2.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    from sim_backend.dem.stability import CASES, run_case

    if args.list:
        for name in CASES:
            print(name)
        return 0
    names = args.case or list(CASES)
    for name in names:
        if name not in CASES:
            raise CliError(f"--case: unknown case {name!r} (choose from {', '.join(CASES)})")
    if args.plot is not None:
        try:
            args.plot.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise CliError(f"--plot: cannot create {args.plot} ({exc.strerror})") from None
    t0 = time.perf_counter()
    head = f"{'case':<16} {'kind':<7} {'dt_us':>7} {'max|v| m/s':>10} {'E resid':>8} {'window':>8}"
    print(head + "  verdict")
    n_fail = 0
    for name in names:
        res = run_case(name, fast=args.fast)
        verdict = "PASS" if res.passed else "FAIL"
        n_fail += not res.passed
        print(
            f"{res.name:<16} {res.kind:<7} {res.dt_s * 1e6:>7.3g} {res.max_abs_v_m_s:>10.3g} "
            f"{res.energy_residual_rel:>8.2g} {res.window_s * 1e3:>6.4g}ms  {verdict}: {res.reason}"
        )
        print(f"    stresses: {res.stresses}")
        print(f"    step: {res.integrator}, {res.step_reason}")
        for note in res.notes:
            print(f"    {note}")
        print(f"    wall {res.wall_s:.1f} s")
        if args.plot is not None:
            _figure(res, args.plot / f"{res.name}.png")
    print(f"{len(names) - n_fail}/{len(names)} cases pass ({time.perf_counter() - t0:.0f} s)")
    return 0 if n_fail == 0 else 1
